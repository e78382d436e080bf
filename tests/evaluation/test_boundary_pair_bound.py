"""`kinfu eval segment --t-eval`: the boundary's pair searches within T_eval are estimated before they run
(core.point_pairs); a T_eval joining every point to every other is refused naming --t-eval, not a search
that runs out of memory."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core import point_pairs
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.segments import boundary_set, match_boundaries
from kinfu_cli.io.labelled_cloud import write_labelled_cloud
from tests.conftest import one_line_error


def _cloud(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.uniform(0.0, 1.0, (n, 3))
    return points, (points[:, 0] > 0.5).astype(int)


def test_a_t_eval_spanning_the_cloud_is_refused_by_the_cli(tmp_path, monkeypatch):
    """3000 points and T_eval 1 m: about 3.5e6 pairs, over the bound lowered to 1e6 to keep the test small (the
    default 2e7 is 12 k such points)."""
    monkeypatch.setattr(point_pairs, "MAX_POINT_PAIRS", 1_000_000)
    points, labels = _cloud()
    seg = write_labelled_cloud(tmp_path / "seg.ply", points, labels)
    gt = write_labelled_cloud(tmp_path / "gt.ply", points, 1 - labels)
    res = CliRunner().invoke(cli, ["eval", "segment", str(seg), "--ground-truth", str(gt), "--t-eval", "1"])
    one_line_error(res, "--t-eval: 1 m joins about", "among the 3000 points scored", "default 0.02 m")
    ok = CliRunner().invoke(cli, ["eval", "segment", str(seg), "--ground-truth", str(gt), "--t-eval", "0.02"])
    assert ok.exit_code == 0, ok.output


def test_the_boundary_searches_name_t_eval(monkeypatch):
    monkeypatch.setattr(point_pairs, "MAX_POINT_PAIRS", 1_000_000)
    points, labels = _cloud()
    with pytest.raises(ConfigError) as err:
        boundary_set(points, labels, t_eval=1.0)
    assert err.value.parameter == "t_eval"
    everything = np.arange(len(points))  # boundaries as large as the cloud, matched within 1 m
    with pytest.raises(ConfigError) as err:
        match_boundaries(points, everything, everything, t_eval=1.0)
    assert err.value.parameter == "t_eval" and "ground-truth boundary points" in str(err.value)
    assert len(boundary_set(points, labels, t_eval=0.1)) > 0  # ~19 k pairs: searched
