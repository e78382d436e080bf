"""segment, diff and nbv take a `kinfu fuse` output folder where they take its volume.npz (as grasp takes a
segment folder). Before: `kinfu segment FUSE_DIR` was refused with click's usage block ("is a directory"), and nbv
said the folder was no volume file."""

from __future__ import annotations

import json

from click.testing import CliRunner
from conftest import one_line_error, small_tabletop_volume

from kinfu_cli.cli import cli


def _fuse_folder(path):
    vol = small_tabletop_volume(3)
    path.mkdir()
    vol.save(path / "volume.npz")
    return path


def test_a_fuse_folder_stands_for_its_volume(tmp_path):
    fused = _fuse_folder(tmp_path / "fuse")
    run = CliRunner().invoke
    by_file = run(cli, ["segment", str(fused / "volume.npz"), "-o", str(tmp_path / "a"), "--no-superquadrics",
                        "--quiet"])
    by_folder = run(cli, ["segment", str(fused), "-o", str(tmp_path / "b"), "--no-superquadrics", "--quiet"])
    assert by_file.exit_code == 0 and by_folder.exit_code == 0, by_folder.output
    a, b = (json.loads((tmp_path / n / "segments.json").read_text()) for n in "ab")
    assert len(a["segments"]) >= 3 and a["segments"] == b["segments"]
    res = run(cli, ["diff", str(fused), str(fused / "volume.npz"), "-o", str(tmp_path / "d"), "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["regions"] == []  # a volume against itself: nothing changed


def test_a_folder_without_a_volume_is_one_line(tmp_path):
    (tmp_path / "empty").mkdir()
    for args in (["segment", str(tmp_path / "empty"), "-o", str(tmp_path / "s")],
                 ["nbv", str(tmp_path / "empty"), "--mode", "objects"]):
        res = CliRunner().invoke(cli, args)
        line = one_line_error(res)
        assert "a folder without volume.npz or ternary.npz" in line and str(tmp_path / "empty") in line
