"""A radius spanning the cloud is refused before the pair search (it made N^2 / 2 pairs and ran out of memory),
and the support plane's span test holds on a cloud kilometres wide (its dense cell grid ran out of memory)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.segmentation.segments import MAX_ADJACENCY_PAIRS, _spans, adjacency_pairs


def _cloud(n, side, seed=0):
    return np.random.default_rng(seed).uniform(0.0, side, size=(n, 3))


def test_radius_spanning_the_cloud_is_refused_with_the_numbers():
    points = _cloud(8000, 1.0)  # 8000^2 / 2 = 3.2e7 pairs at 10 m
    with pytest.raises(ConfigError) as err:
        adjacency_pairs(points, 10.0)
    assert err.value.parameter == "adjacency_radius"
    message = str(err.value)
    assert "8000 surface points" in message and f"{MAX_ADJACENCY_PAIRS:.3g}" in message
    expected = float(message.split("about ")[1].split()[0])
    assert 3.0e7 < expected < 3.4e7


def test_a_radius_near_the_spacing_gives_the_same_pairs():
    points = _cloud(8000, 1.0)
    pairs = adjacency_pairs(points, 0.05)
    assert np.array_equal(np.sort(pairs, axis=0), np.sort(cKDTree(points).query_pairs(0.05, output_type="ndarray"),
                                                            axis=0))


def test_span_of_a_plane_kilometres_wide():
    grid = np.arange(0.0, 1.0, 0.01)
    x, y = np.meshgrid(grid, grid, indexing="ij")
    patch = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    far = patch + [1e6, 1e6, 0.0]  # a second patch 1000 km away: 5e7 cells a side between them
    assert _spans(np.concatenate([patch, far]), np.array([0.0, 0.0, 1.0]), 0.4, 0.02)
    # two touching halves (8-neighbourhood over the cells) are one patch; a gap of cells splits them
    half = patch[patch[:, 0] < 0.5]
    assert _spans(np.concatenate([half, half + [0.5, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]), 0.6, 0.02)
    assert not _spans(np.concatenate([half, half + [0.6, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0]), 0.6, 0.02)
