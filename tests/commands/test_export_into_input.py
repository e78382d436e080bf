"""`kinfu export` into the folder it reads: frames written inside a ROS 2 bag folder joined the recording, and a
trajectory written into a fuse output was replaced by that folder's next fuse run. Refused before any work,
naming --out; the input folder is left as it was."""

from __future__ import annotations

import shutil

from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli


def _listing(folder):
    return sorted((p.relative_to(folder), p.stat().st_size) for p in folder.rglob("*"))


def test_export_into_the_recording_folder_is_refused(sample_dir, tmp_path):
    rec = tmp_path / "bag"
    shutil.copytree(sample_dir / "recording_ros2", rec)
    before = _listing(rec)
    for extra in ([], ["--trajectory", "tum"]):
        out = rec / ("gt.tum" if extra else "frames")
        one_line_error(CliRunner().invoke(cli, ["export", str(rec), "-o", str(out), "-q", *extra]),
                       "--out", "inside the input folder")
    assert _listing(rec) == before


def test_trajectory_into_the_fuse_folder_is_refused(tmp_path):
    fuse = tmp_path / "fuse"
    fuse.mkdir()
    (fuse / "trajectory.tum").write_text("")
    one_line_error(CliRunner().invoke(cli, ["export", str(fuse), "--trajectory", "tum", "-o",
                                            str(fuse / "sub" / "est.tum")]), "--out", "inside the input folder")
    assert sorted(p.name for p in fuse.iterdir()) == ["trajectory.tum"]
