"""`kinfu export --trajectory tum`: a recording's own camera poses and a fuse run's trajectory.tum as TUM files
evo reads; the ATE between them, computed here from the two files, is the one fuse reports."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.io.tum import read_tum

WINDOW = ("--end", "4", "--every", "2")  # 4 s of the 5 Hz sample, every other frame: 8 frames, 2 cm voxels


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def hint_run(sample_dir, tmp_path_factory):
    """ICP tracking started from the recorded poses (--pose hint) on the sample, and the recorded poses."""
    tmp = tmp_path_factory.mktemp("traj")
    rec = sample_dir / "recording.mcap"
    res = run("fuse", rec, "-o", tmp / "fuse", "--pose", "hint", "--voxel-size", "0.02", *WINDOW, "--quiet")
    assert res.exit_code == 0, res.output
    res = run("export", rec, "--trajectory", "tum", "-o", tmp / "gt.tum", *WINDOW, "--json")
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    res = run("export", tmp / "fuse", "--trajectory", "tum", "-o", tmp / "est.tum")
    assert res.exit_code == 0, res.output
    return tmp, summary


@pytest.mark.slow
def test_fused_trajectory_against_recorded_poses_matches_fuse_report(hint_run):
    tmp, summary = hint_run
    report = json.loads((tmp / "fuse" / "report.json").read_text())
    assert "trajectory.tum" in report["outputs"]
    gt_stamps, gt = read_tum(tmp / "gt.tum")
    est_stamps, est = read_tum(tmp / "est.tum")
    fused_stamps, fused = read_tum(tmp / "fuse" / "trajectory.tum")
    # the exported copy is the fuse folder's trajectory, line for line in value
    assert np.array_equal(est_stamps, fused_stamps) and np.abs(est - fused).max() < 1e-9
    # one pose per fused frame, stamped as the recording's depth frames: every one has its recorded pose
    assert len(est) == report["frames"]["used"] == summary["poses"] == len(gt) >= 6
    assert np.array_equal(est_stamps, gt_stamps)
    # the first frame anchors hint tracking at its recorded pose; the tracked ones give fuse's ATE
    assert np.abs(est[0] - gt[0]).max() < 1e-6
    tracked = {f["stamp_ns"] for f in report["tracking"]["frames"] if not f["lost"]}
    sel = np.array([s in tracked for s in est_stamps])
    err = np.linalg.norm(est[sel, :3, 3] - gt[sel, :3, 3], axis=1)
    ate = report["tracking"]["ate_vs_given_m"]
    assert ate["frames"] == sel.sum() and ate["rmse"] == pytest.approx(np.sqrt(np.mean(err ** 2)), abs=2e-5)
    assert ate["max"] == pytest.approx(err.max(), abs=2e-5)
    # evo_ape without alignment computes the same RMSE over the same pairs; the first frame adds a zero
    all_err = np.linalg.norm(est[:, :3, 3] - gt[:, :3, 3], axis=1)
    assert np.sqrt(np.sum(all_err ** 2) / len(all_err)) == pytest.approx(ate["rmse"] * np.sqrt(sel.sum() / len(all_err)),
                                                                       abs=2e-5)


@pytest.mark.slow
def test_recorded_trajectory_is_the_tf_pose_of_each_depth_frame(hint_run, sample_dir):
    """The ground-truth file holds the camera's TF pose at each depth frame: the same as `kinfu export`'s
    frame folder pose files."""
    tmp, summary = hint_run
    res = run("export", sample_dir / "recording.mcap", "-o", tmp / "frames", *WINDOW, "--quiet", "--json")
    assert res.exit_code == 0, res.output
    listing = json.loads(res.output)["list"]
    stamps, gt = read_tum(tmp / "gt.tum")
    assert [f["stamp_ns"] for f in listing] == stamps.tolist()
    for f, T in zip(listing, gt):
        assert np.abs(np.loadtxt(tmp / "frames" / f"frame-{f['index']:06d}.pose.txt") - T).max() < 1e-8
    assert summary["world_frame"] == "world" and summary["kind"] == "recording"


def test_trajectory_errors_are_one_line(sample_dir, tmp_path):
    folder = tmp_path / "old_fuse"
    folder.mkdir()
    (folder / "report.json").write_text("{}")
    one_line_error(run("export", folder, "--trajectory", "tum", "-o", tmp_path / "x.tum"), "trajectory.tum")
    one_line_error(run("export", sample_dir / "recording.mcap", "--trajectory", "tum", "-o", tmp_path / "y.tum",
                       "--pose-source", "none"), "--pose-source")
    assert not (tmp_path / "x.tum").exists() and not (tmp_path / "y.tum").exists()
