"""Neighbour-pair searches are estimated before they run: a radius spanning the cloud is refused with the numbers
(N^2 / 2 pairs ran out of memory), a radius near the spacing gives the same pairs as scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from kinfu_cli.core import point_pairs
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.point_pairs import MAX_POINT_PAIRS, bounded_pairs, check_pair_count, estimated_pairs


def _cloud(n, side=1.0, seed=0):
    return np.random.default_rng(seed).uniform(0.0, side, size=(n, 3))


def test_the_estimate_is_near_the_true_count():
    tree = cKDTree(_cloud(20000))
    for radius in (0.03, 0.1):
        true = len(tree.query_pairs(radius, output_type="ndarray"))
        assert abs(estimated_pairs(tree, radius) - true) < 0.1 * true
    assert estimated_pairs(tree, 10.0) == pytest.approx(20000 * 19999 / 2)
    # (query, point) pairs: each query point sees all 20000 at 10 m
    assert estimated_pairs(tree, 10.0, queries=_cloud(5000, seed=1)) == pytest.approx(5000 * 20000)
    assert estimated_pairs(cKDTree(np.zeros((1, 3))), 1.0) == 0.0


def test_a_radius_spanning_the_cloud_is_refused_naming_the_parameter():
    points = _cloud(8000)  # 3.2e7 pairs at 10 m
    with pytest.raises(ConfigError) as err:
        bounded_pairs(points, 10.0, what="test points", parameter="radius_x", hint="expected a small radius")
    assert err.value.parameter == "radius_x"
    message = str(err.value)
    assert message.startswith("radius_x: 10 m joins about 3.2e+07 point pairs among the 8000 test points")
    assert f"at most {MAX_POINT_PAIRS:.3g}" in message and message.endswith("expected a small radius")


def test_the_error_class_and_limit_are_the_callers():
    tree = cKDTree(_cloud(2000))
    with pytest.raises(VolumeError) as err:
        check_pair_count(tree, 10.0, what="points", hint="a broken input", error=VolumeError, limit=1000)
    assert err.value.parameter is None and "about 2e+06 point pairs" in str(err.value)
    assert check_pair_count(tree, 0.01, what="points", hint="", limit=1000) < 1000


def test_the_module_bound_applies_at_call_time(monkeypatch):
    monkeypatch.setattr(point_pairs, "MAX_POINT_PAIRS", 100)
    with pytest.raises(ConfigError, match="at most 100,"):
        bounded_pairs(_cloud(500), 10.0, what="points", hint="")


def test_a_bounded_search_gives_scipys_pairs():
    points = _cloud(8000)
    for p in (2.0, np.inf):
        got = bounded_pairs(points, 0.05, what="points", hint="", p=p)
        want = cKDTree(points).query_pairs(0.05, p=p, output_type="ndarray")
        assert len(got) > 1000 and np.array_equal(np.sort(got, axis=0), np.sort(want, axis=0))
