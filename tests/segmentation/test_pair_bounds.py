"""The neighbour-pair searches of `kinfu segment` past the adjacency (saliency's isolation, bridges, the
superquadric outlier filter) are estimated before they run (core.point_pairs): a radius joining every point to
every other is refused naming its parameter, a doubtful input naming the input, instead of exhausting memory."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core import point_pairs
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.segmentation.bridges import BridgeParams, join_across_unknown
from kinfu_cli.segmentation.saliency import segment_saliency
from kinfu_cli.segmentation.superquadric import SegmentError, fit_superquadric, remove_outliers


def _cloud(n, side=1.0, seed=0):
    return np.random.default_rng(seed).uniform(0.0, side, size=(n, 3))


def test_isolation_threshold_spanning_the_scene_is_refused_by_the_cli(tmp_path):
    labels = np.full((100, 100, 12), -1, np.int8)  # a 1 m slab with a box on it: 10 k surface points
    labels[:, :, :4] = 1
    labels[40:55, 40:55, 4:9] = 1
    save_ternary(tmp_path / "slab.npz", TernaryGrid(labels, np.zeros(3), 0.01))
    out = tmp_path / "seg"
    res = CliRunner().invoke(cli, ["segment", str(tmp_path / "slab.npz"), "-o", str(out), "--quiet",
                                   "--no-superquadrics", "--isolation-threshold", "5"])
    assert res.exit_code == 2 and "Traceback" not in res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: --isolation-threshold: 5 m joins about ")
    assert "surface points (at most 2e+07" in lines[0] and "default 0.02 m" in lines[0]


def test_isolation_threshold_is_named_by_the_library():
    points = _cloud(8000)
    with pytest.raises(ConfigError) as err:
        segment_saliency(points, np.arange(8000) % 3, b_th=10.0)
    assert err.value.parameter == "isolation_threshold" and "8000 surface points" in str(err.value)
    assert len(segment_saliency(points, np.arange(8000) % 3, b_th=0.02)) == 3


def _no_space():
    return (lambda x: np.zeros(len(x), np.int8)), 0.01


def test_a_bridge_gap_spanning_the_cloud_is_refused():
    points = _cloud(8000)
    normals = np.tile([0.0, 0.0, 1.0], (8000, 1))
    with pytest.raises(ConfigError) as err:
        join_across_unknown(np.arange(8000) % 2, points, normals, None, _no_space(), 0.0, BridgeParams(max_gap=1.0))
    message = str(err.value)
    assert err.value.parameter == "bridge_gap" and "point pairs among the 8000 segmented points" in message
    assert 2.5e7 < float(message.split("about ")[1].split()[0]) < 3.2e7  # 1 m of the unit cube's 1.7 m diagonal


def test_a_cloud_too_dense_for_the_bridge_colour_means_names_the_input(monkeypatch):
    """2000 points in a 1 cm cube in 25 segments: each of the 3000 bridge ends would average all 2000 points
    (6e6 in all; the bound lowered to 1e5 keeps the test small)."""
    monkeypatch.setattr(point_pairs, "MAX_POINT_PAIRS", 100_000)
    points = _cloud(2000, side=0.01)
    normals = np.tile([0.0, 0.0, 1.0], (2000, 1))
    seg = np.arange(2000) % 25
    with pytest.raises(VolumeError) as err:
        join_across_unknown(seg, points, normals, np.full((2000, 3), 0.5), _no_space(), 0.0,
                            BridgeParams(max_gap=0.001))
    assert err.value.parameter is None
    assert "among the 2000 surface points" in str(err.value) and "one surface point per voxel" in str(err.value)


def test_piled_up_duplicate_points_are_a_segment_error_not_a_pair_search():
    points = np.concatenate([np.full((7000, 3), 0.05), _cloud(100, side=0.1)])  # median spacing 0
    with pytest.raises(SegmentError) as err:
        fit_superquadric(points)
    message = str(err.value)
    assert "about 2.45e+07 point pairs among the 7100 points of the segment" in message
    assert "duplicate points" in message


def test_a_given_outlier_radius_spanning_the_segment_is_refused():
    points = _cloud(8000)
    with pytest.raises(ConfigError) as err:
        remove_outliers(points, eps=10.0)
    assert err.value.parameter == "eps"
    assert remove_outliers(points, eps=0.05).sum() > 7000
