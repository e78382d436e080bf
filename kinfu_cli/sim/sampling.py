"""Uniform random points on a triangle mesh: the one surface sampler of ground-truth meshes.

Area-weighted triangle choice, then uniform barycentric coordinates (sqrt trick); every caller that needs
"the true surface as points" (completeness, visibility, errors inside a POI sphere) draws them here.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.errors import ConfigError

MAX_SAMPLES = 3_000_000


def sample_triangles(vertices: np.ndarray, triangles: np.ndarray, count: int, seed: int = 0
                     ) -> tuple[np.ndarray, np.ndarray]:
    """`count` uniform random points on the triangles (vertices (N, 3), triangles (M, 3) indices) and the unit
    normal of the triangle each lies on (winding order: outward for the ground-truth meshes). Empty arrays
    when the triangles have no area."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cr = np.cross(b - a, c - a)
    area2 = np.linalg.norm(cr, axis=1)
    if len(f) == 0 or not area2.sum() > 0 or count < 1:
        return np.zeros((0, 3)), np.zeros((0, 3))
    rng = np.random.default_rng(seed)
    tri = rng.choice(len(f), size=int(count), p=area2 / area2.sum())
    r1, r2 = rng.random(int(count)), rng.random(int(count))
    s = np.sqrt(r1)
    w0, w1, w2 = 1 - s, s * (1 - r2), s * r2
    pts = w0[:, None] * a[tri] + w1[:, None] * b[tri] + w2[:, None] * c[tri]
    normals = cr[tri] / np.maximum(area2[tri], 1e-30)[:, None]
    return pts, normals


def surface_area(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Total area (m^2) of the triangles."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    return 0.5 * float(np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum())


def sample_surface(vertices: np.ndarray, triangles: np.ndarray, spacing: float = 0.005, seed: int = 0,
                   max_samples: int = MAX_SAMPLES) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random points on a mesh, one per spacing^2 of area on average (at most max_samples: the spacing
    grows instead), and their triangles' unit normals (see sample_triangles)."""
    if not spacing > 0:
        raise ConfigError(f"expected a positive distance in metres, got {spacing}", parameter="spacing")
    total = surface_area(vertices, triangles)
    if total <= 0:
        return np.zeros((0, 3)), np.zeros((0, 3))
    # total / spacing / spacing: a spacing of 1e-300 squares to 0 (a division by zero), its quotient to inf (capped)
    return sample_triangles(vertices, triangles, int(round(min(max_samples, max(1.0, total / spacing / spacing)))),
                            seed)
