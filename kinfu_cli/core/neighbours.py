"""Neighbourhoods of points: nearest-neighbour transfer within a distance (the labels evaluation carries onto
segmented points, the colours segmentation lends to never-coloured points) and the cells of a regular grid (one
point per cell to thin a cloud, supervoxel seeds)."""

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


def grid_cells(points: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(first point of each occupied `cell`-sized grid cell, cell id per point), cells in lexicographic order
    (as np.unique(axis=0) gives them, through one int64 key: several times faster)."""
    c = np.floor(points / cell).astype(np.int64)
    c -= c.min(axis=0)
    span = c.max(axis=0) + 1
    key = (c[:, 0] * span[1] + c[:, 1]) * span[2] + c[:, 2]
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    return first, inv.ravel()
