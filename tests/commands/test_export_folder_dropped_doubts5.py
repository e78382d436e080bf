"""The frame-folder `kinfu export` warns of the depth frames it dropped, as `--trajectory tum` does: it said so
only in its summary line and stats, so with --json (and in frames.json) nothing warned."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.recordings import make_recording


def test_dropped_frames_warn_in_the_json_summary_and_frames_json(tmp_path):
    rec = make_recording(tmp_path / "late.mcap", n=12, tf_from=0.2)  # TF from 0.2 s: the first frames have no pose
    out = tmp_path / "frames"
    res = CliRunner().invoke(cli, ["export", str(rec), "-o", str(out), "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    stats = doc["stats"]
    assert 0 < stats["dropped_total"] < 12 and doc["frames"] == 12 - stats["dropped_total"]
    said = [w for w in doc["warnings"] if "dropped" in w]
    assert len(said) == 1
    assert f"{stats['dropped_total']} of the 12 depth frames dropped" in said[0] and "late.mcap" in said[0]
    reason, n = next(iter(stats["dropped"].items()))
    assert f"{reason}: {n}" in said[0] and "the folder has no frame at their stamps" in said[0]
    assert f"kinfu: warning: {said[0]}" in res.stderr
    assert json.loads((out / "frames.json").read_text())["warnings"] == doc["warnings"]


def test_a_whole_export_says_nothing(tmp_path):
    rec = make_recording(tmp_path / "ok.mcap", n=6)
    res = CliRunner().invoke(cli, ["export", str(rec), "-o", str(tmp_path / "frames"), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["warnings"] == [] and "warning" not in res.stderr
