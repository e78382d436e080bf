"""Whether a mesh's faces index its own vertices. open3d's readers take a face that indexes past the vertices (a
damaged or hand-edited file) without a word, and a distance query then reads outside the vertex array; localize's
model check and eval fusion's mesh reader both refuse such a mesh with this reason."""

from __future__ import annotations

import numpy as np


def faces_outside_vertices(n_vertices: int, triangles: np.ndarray) -> str | None:
    """Why faces (M, 3) of a mesh of `n_vertices` vertices index outside them, or None (also without faces: a point
    cloud)."""
    tri = np.asarray(triangles)
    if tri.size == 0:
        return None
    lo, hi = int(tri.min()), int(tri.max())
    if lo < 0 or hi >= n_vertices:
        return f"mesh faces index vertices {lo} to {hi}, but it has {n_vertices} (a damaged file?)"
    return None
