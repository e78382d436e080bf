"""`kinfu eval nbv` on a kinfu synth folder without a hand trajectory says its POIs are the true changes (they
were silently, under the default --pois-from gmm-as) or refuses an explicit gmm-as; --quiet prints only warnings
and errors (the result tables were printed)."""

from __future__ import annotations

import json

from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli

TINY = ["--strategy", "fixed", "--views", "1", "--voxel-size", "0.025", "--width", "80", "--height", "60",
        "--scan-every", "4", "--lon-step", "90", "--lat-step", "45", "--roll-step", "180", "--no-noise"]


def _without_hand(sample_dir, tmp_path):
    folder = tmp_path / "gt"
    folder.mkdir()
    for src in (sample_dir / "ground_truth").iterdir():
        if src.name != "hand.traj":
            (folder / src.name).symlink_to(src)
    return folder


def test_no_hand_trajectory_warns_that_the_pois_are_the_true_changes(sample_dir, tmp_path):
    out = tmp_path / "e.json"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(_without_hand(sample_dir, tmp_path)), *TINY, "--quiet",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: warning: "), res.output  # --quiet: no table
    assert "true changes" in lines[0] and "no hand trajectory" in lines[0]
    doc = json.loads(out.read_text())
    assert doc["config"]["pois_from"] == "truth"
    assert len(doc["warnings"]) == 1 and "true changes" in doc["warnings"][0]


def test_no_hand_trajectory_with_gmm_as_given_is_refused(sample_dir, tmp_path):
    res = CliRunner().invoke(cli, ["eval", "nbv", str(_without_hand(sample_dir, tmp_path)), *TINY,
                                   "--pois-from", "gmm-as", "--quiet", "-o", str(tmp_path / "e.json")])
    one_line_error(res, "--pois-from", "no hand trajectory", "hand.traj")
    assert not (tmp_path / "e.json").exists()


def test_quiet_prints_nothing_and_json_still_prints(sample_dir, tmp_path):
    out = tmp_path / "e.json"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(sample_dir), *TINY, "--quiet", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert res.output.strip() == "" and json.loads(out.read_text())["warnings"] == []
    res = CliRunner().invoke(cli, ["eval", "nbv", str(sample_dir), *TINY, "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    assert "fixed" in json.loads(res.output)["strategies"]
