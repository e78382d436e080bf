"""A mesh's signed distance sampled once on a grid from open3d's BVH (value and outward unit normal of the
closest point at every node), and numba lookups of distance and closest surface point from it.

The filters ask ~10^6 closest-point / distance queries per run; a trilinear lookup is ~20x cheaper than a BVH
query and runs inside the filters' numba kernels (benchmarks/bench_localize.py measures ratio and error).
Inside the grid: distance = |trilinear signed distance|, closest point = p - s n / |n| with n the trilinear
node normal (the nearest node's normal where the interpolated one cancels, on the medial axis). Outside the
grid (poses far off the points, hopeless for the likelihood anyway) the query is clamped onto the grid's box,
its closest point taken there, and the distance is to that surface point (exact along a face normal, an upper
bound elsewhere).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange


@dataclass(frozen=True)
class DistanceField:
    """lo (3,) grid origin, step (m), sdf (nx, ny, nz) signed distance (negative inside), normals
    (nx, ny, nz, 3) outward unit normal of each node's closest surface point."""

    lo: np.ndarray
    step: float
    sdf: np.ndarray
    normals: np.ndarray

    def distances(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) model-frame points -> unsigned distance to the surface (...)."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        out = np.empty(len(pts))
        _distances(pts, self.lo, self.step, self.sdf, self.normals, out)
        return out.reshape(np.shape(points)[:-1])

    def closest_points(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) model-frame points -> closest surface points (..., 3)."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        out = np.empty_like(pts)
        _closest(pts, self.lo, self.step, self.sdf, self.normals, out)
        return out.reshape(np.shape(points))


def sample_field(vertices: np.ndarray, signed_distance, closest_points, cells: int = 64,
                 margin: float = 0.3) -> DistanceField:
    """Sample `signed_distance` / `closest_points` (the BVH's, on (M, 3) arrays) on a grid of `cells` per side over
    the vertices' bounding box grown by `margin` diameters."""
    vmin, vmax = vertices.min(0), vertices.max(0)
    diameter = float(np.linalg.norm(vmax - vmin))
    lo = vmin - margin * diameter
    hi = vmax + margin * diameter
    step = float((hi - lo).max() / (cells - 1))
    shape = np.ceil((hi - lo) / step).astype(int) + 1
    axes = [lo[k] + step * np.arange(shape[k]) for k in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    sdf = signed_distance(grid)
    near = closest_points(grid)
    normals = grid - near
    norm = np.linalg.norm(normals, axis=1)
    ok = norm > 1e-9
    normals[ok] /= (norm[ok] * np.sign(sdf[ok]) + (sdf[ok] == 0))[:, None]
    if not ok.all():  # nodes on the surface: the grid gradient
        g = np.stack(np.gradient(sdf.reshape(shape), step), -1).reshape(-1, 3)
        gn = np.linalg.norm(g[~ok], axis=1, keepdims=True)
        normals[~ok] = g[~ok] / np.maximum(gn, 1e-12)
    return DistanceField(lo.astype(np.float64), step, sdf.reshape(shape).astype(np.float64),
                         np.ascontiguousarray(normals.reshape(*shape, 3), dtype=np.float64))


@njit(cache=True)
def _clamp(v, hi):
    if v < 0.0:
        return 0.0, True
    if v > hi:
        return hi, True
    return v, False


@njit(cache=True)
def lookup(p0, p1, p2, lo, step, sdf, normals, out):
    """Closest surface point of (p0, p1, p2) into out[0:3]; returns the unsigned distance."""
    nx, ny, nz = sdf.shape
    u0, c0 = _clamp((p0 - lo[0]) / step, nx - 1.000001)
    u1, c1 = _clamp((p1 - lo[1]) / step, ny - 1.000001)
    u2, c2 = _clamp((p2 - lo[2]) / step, nz - 1.000001)
    i, j, l = int(u0), int(u1), int(u2)
    fx, fy, fz = u0 - i, u1 - j, u2 - l
    s = 0.0
    n0 = 0.0
    n1 = 0.0
    n2 = 0.0
    for a in range(2):
        wa = fx if a else 1.0 - fx
        for b in range(2):
            wb = fy if b else 1.0 - fy
            for c in range(2):
                w = wa * wb * (fz if c else 1.0 - fz)
                s += w * sdf[i + a, j + b, l + c]
                n0 += w * normals[i + a, j + b, l + c, 0]
                n1 += w * normals[i + a, j + b, l + c, 1]
                n2 += w * normals[i + a, j + b, l + c, 2]
    nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if nn < 0.3:  # the medial axis: normals cancel; take the nearest node's
        a, b, c = int(fx + 0.5), int(fy + 0.5), int(fz + 0.5)
        n0, n1, n2 = normals[i + a, j + b, l + c, 0], normals[i + a, j + b, l + c, 1], normals[i + a, j + b, l + c, 2]
        nn = 1.0
    out[0] = lo[0] + u0 * step - s * n0 / nn
    out[1] = lo[1] + u1 * step - s * n1 / nn
    out[2] = lo[2] + u2 * step - s * n2 / nn
    if not (c0 or c1 or c2):
        return abs(s)
    return math.sqrt((p0 - out[0]) ** 2 + (p1 - out[1]) ** 2 + (p2 - out[2]) ** 2)


@njit(cache=True, parallel=True)
def _distances(pts, lo, step, sdf, normals, out):
    tmp = np.empty((pts.shape[0], 3))
    for k in prange(pts.shape[0]):
        out[k] = lookup(pts[k, 0], pts[k, 1], pts[k, 2], lo, step, sdf, normals, tmp[k])


@njit(cache=True, parallel=True)
def _closest(pts, lo, step, sdf, normals, out):
    for k in prange(pts.shape[0]):
        lookup(pts[k, 0], pts[k, 1], pts[k, 2], lo, step, sdf, normals, out[k])
