"""`kinfu eval fusion --spacing` coarser than the distance threshold completeness is measured at: `--spacing 1`
left 6 observed samples of the sample scene and reported completeness 1.0 with no word. Now a warning names both
values and the samples the completeness rests on."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation.reconstruction import coarse_spacing_warnings


def test_a_spacing_coarser_than_the_threshold_is_warned_with_both_values(sample_dir, tmp_path):
    out = tmp_path / "fusion.json"
    res = CliRunner().invoke(cli, ["eval", "fusion", str(sample_dir / "ground_truth" / "scene_after.ply"),
                                   "--ground-truth", str(sample_dir), "--spacing", "1", "--quiet", "-o", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    observed = doc["reconstruction"]["samples_observed"]
    assert doc["reconstruction"]["spacing"] == 1.0 and observed < 50
    coarse = [w for w in doc["warnings"] if "coarser than the distance threshold" in w]
    assert len(coarse) == 1
    assert "spacing 1 m" in coarse[0] and "threshold 0.01 m" in coarse[0]
    assert f"{observed} observed samples" in coarse[0]
    assert f"kinfu: warning: {coarse[0]}" in res.output


def test_a_spacing_at_most_the_threshold_says_nothing():
    assert coarse_spacing_warnings(0.005, 0.01, 100_000) == []
    assert coarse_spacing_warnings(0.01, 0.01, 100_000) == []
    assert "spacing 0.02 m" in coarse_spacing_warnings(0.02, 0.01, 1)[0]
    assert "1 observed sample " in coarse_spacing_warnings(0.02, 0.01, 1)[0]
