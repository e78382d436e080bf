"""Nearest-neighbour transfer within a distance: one place for the labels evaluation carries onto segmented
points and the colours segmentation lends to never-coloured points."""

from __future__ import annotations

import numpy as np


def transfer_nearest(src_points: np.ndarray, src_values: np.ndarray, dst_points: np.ndarray, max_distance: float,
                     out: np.ndarray) -> np.ndarray:
    """out[i] = src_values[j] for each destination point i whose nearest source point j lies within max_distance;
    the other rows of `out` (one per destination point) are left as they are. Returns the distances (inf where
    no source point is that near)."""
    from scipy.spatial import cKDTree  # only the callers that transfer need it

    dist, idx = cKDTree(np.asarray(src_points, dtype=np.float64)).query(
        np.asarray(dst_points, dtype=np.float64), distance_upper_bound=max_distance)
    hit = np.isfinite(dist)
    out[hit] = np.asarray(src_values)[idx[hit]]
    return dist
