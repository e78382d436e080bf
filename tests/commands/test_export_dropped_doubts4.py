"""`kinfu export --trajectory tum` says how many depth frames it left out and why, as fuse does: a camera pose
missing at some frames (TF starting late) gave a shorter trajectory without a word."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.tum import read_tum
from tests.recordings import make_recording


def test_frames_without_a_pose_are_counted_in_a_warning(tmp_path):
    rec = make_recording(tmp_path / "late.mcap", n=12, tf_from=0.2)  # TF from 0.2 s: the first frames have no pose
    out = tmp_path / "gt.tum"
    res = CliRunner().invoke(cli, ["export", str(rec), "--trajectory", "tum", "-o", str(out), "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    stats = doc["stats"]
    assert 0 < stats["dropped_total"] < 12 and len(read_tum(out)[0]) == 12 - stats["dropped_total"]
    said = [w for w in doc["warnings"] if "dropped" in w]
    assert len(said) == 1
    assert f"{stats['dropped_total']} of the 12 depth frames dropped" in said[0] and "late.mcap" in said[0]
    reason, n = next(iter(stats["dropped"].items()))
    assert f"{reason}: {n}" in said[0]
    assert f"kinfu: warning: {said[0]}" in res.stderr


def test_a_whole_trajectory_says_nothing(tmp_path):
    rec = make_recording(tmp_path / "ok.mcap", n=6)
    res = CliRunner().invoke(cli, ["export", str(rec), "--trajectory", "tum", "-o", str(tmp_path / "gt.tum"),
                                   "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["warnings"] == [] and "warning" not in res.stderr
