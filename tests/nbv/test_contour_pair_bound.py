"""Contour voxels are grouped over the pairs within distance_th; a distance spanning the frontier is refused
before the pair search (core.point_pairs) instead of holding every pair of contour voxels."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.nbv.contours import extract_contours


def _floor_under_unknown():
    """A 120 x 120 voxel floor, one observed empty layer over it, a checkerboard of unknown and empty voxels above:
    the 7200 empty voxels under an unknown one are contour voxels."""
    labels = np.full((120, 120, 4), -1, np.int8)
    labels[:, :, 0] = 1
    i, j = np.meshgrid(np.arange(120), np.arange(120), indexing="ij")
    labels[:, :, 2][(i + j) % 2 == 0] = 0
    return labels


def test_a_distance_spanning_the_frontier_is_refused():
    with pytest.raises(ConfigError) as err:
        extract_contours(_floor_under_unknown(), np.zeros(3), 0.01, distance_th=10.0)
    message = str(err.value)
    assert err.value.parameter == "distance_th" and "point pairs among the 7200 contour voxels" in message
    assert "default 1.75 voxels, 0.0175 m" in message


def test_the_default_distance_groups_the_frontier():
    contours = extract_contours(_floor_under_unknown(), np.zeros(3), 0.01)
    assert len(contours.voxel_positions) == 7200 and len(contours.positions) == 576  # 5 cm groups of 5 x 5 voxels
