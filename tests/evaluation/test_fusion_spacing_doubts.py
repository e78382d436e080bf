"""`kinfu eval fusion --spacing`: the true-surface sampler draws at most MAX_SAMPLES points (and at least one), so
a spacing beyond that was changed with no word while the results reported the spacing asked for. Now a warning
gives both spacings and the results report the one sampled at."""

from __future__ import annotations

import json
import math

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation import reconstruction
from kinfu_cli.evaluation.reconstruction import _sampled_spacing

CAP = 20_000  # the sampler's limit in these tests, to keep them fast


def test_too_fine_a_spacing_is_warned_with_both_values(sample_dir, tmp_path, monkeypatch):
    monkeypatch.setattr(reconstruction, "MAX_SAMPLES", CAP)
    out = tmp_path / "fusion.json"
    res = CliRunner().invoke(cli, ["eval", "fusion", str(sample_dir / "ground_truth" / "scene_after.ply"),
                                   "--ground-truth", str(sample_dir), "--spacing", "0.002", "--quiet",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    used = doc["reconstruction"]["spacing"]
    assert doc["reconstruction"]["samples_total"] == CAP and used > 0.01  # ~35 m^2 over 20,000 samples
    warning = next(w for w in doc["warnings"] if "sample spacing" in w)
    assert "0.002 m" in warning and f"{used:.3g} m instead" in warning and f"{CAP}" in warning
    assert f"kinfu: warning: {warning}" in res.output


def test_spacing_within_the_limits_is_kept():
    assert _sampled_spacing(2.0, 80_000, 0.005, "after") == (0.005, [])


def test_spacing_coarser_than_the_surface_is_warned():
    used, warnings = _sampled_spacing(2.0, 1, 9.0, "before")
    assert used == pytest.approx(math.sqrt(2.0))
    assert len(warnings) == 1 and "9 m" in warnings[0] and "1.41 m instead" in warnings[0]
    assert "one sample" in warnings[0]
