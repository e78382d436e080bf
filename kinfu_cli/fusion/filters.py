"""Depth pre-processing: range limits, thin-gap filling, bilateral filter (OpenCV), Kinect V2 shadow and veil filter.

The shadow / veil filter follows Monica's thesis §3.1.3 (digest §2.5): a point is in the IR emitter's
shadow when, scanning a row away from the emitter, its angle seen from the emitter does not exceed
the largest angle met so far (eq. 3.17-3.18, Alg. 5); a veil (mixed) pixel is one whose step to a
4-neighbour lies within Θ_max = 10° of its viewing ray (eq. 3.19).
"""

from __future__ import annotations

import cv2
import numpy as np
from numba import njit, prange

from kinfu_cli.core.errors import ConfigError


def range_filter(depth: np.ndarray, min_depth: float, max_depth: float) -> np.ndarray:
    """float32 depth with NaN and readings outside [min_depth, max_depth] set to 0 (invalid)."""
    d = np.asarray(depth, dtype=np.float32)
    ok = np.isfinite(d) & (d >= min_depth) & (d <= max_depth)
    return np.where(ok, d, np.float32(0)).astype(np.float32)


def bilateral(depth: np.ndarray, diameter: int = 5, sigma_depth: float = 0.03, sigma_space: float = 4.5) -> np.ndarray:
    """Edge-preserving smoothing (cv2.bilateralFilter, sigma_depth in metres); invalid pixels stay invalid
    and do not bleed into valid ones (their value is far outside sigma_depth)."""
    d = np.asarray(depth, dtype=np.float32)
    valid = d > 0
    out = cv2.bilateralFilter(d, int(diameter), float(sigma_depth), float(sigma_space))
    return np.where(valid, out, np.float32(0)).astype(np.float32)


@njit(cache=True, parallel=True)
def _shadow_mask(depth, fx, cx, baseline):
    h, w = depth.shape
    mask = np.zeros((h, w), dtype=np.bool_)
    for v in prange(h):
        best = -np.inf
        if baseline >= 0.0:
            for u in range(w):
                z = depth[v, u]
                if not z > 0.0:
                    continue
                beta = (u - cx) / fx + baseline / z  # x' / z with x' = (u - cx) / fx * z + baseline
                if beta <= best:
                    mask[v, u] = True
                else:
                    best = beta
        else:
            for u in range(w - 1, -1, -1):
                z = depth[v, u]
                if not z > 0.0:
                    continue
                beta = -((u - cx) / fx + baseline / z)
                if beta <= best:
                    mask[v, u] = True
                else:
                    best = beta
    return mask


def shadow_mask(depth: np.ndarray, K: np.ndarray, baseline: float = 0.08) -> np.ndarray:
    """True where a pixel lies in the IR emitter's shadow (Alg. 5). baseline: emitter offset along the
    camera x axis in metres (Kinect V2: about 8 cm; the sign picks the side and the scan direction)."""
    if not np.isfinite(baseline) or baseline == 0:
        raise ConfigError(f"shadow filter baseline: expected a non-zero offset in metres, got {baseline}")
    return _shadow_mask(np.asarray(depth, dtype=np.float32), float(K[0, 0]), float(K[0, 2]), float(baseline))


def veil_mask(depth: np.ndarray, K: np.ndarray, max_angle_deg: float = 10.0) -> np.ndarray:
    """True where a pixel is a veil (mixed) point: the step to some valid 4-neighbour is within
    max_angle_deg of the pixel's viewing ray (eq. 3.19)."""
    d = np.asarray(depth, dtype=np.float64)
    h, w = d.shape
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    P = np.stack([(u - K[0, 2]) / K[0, 0] * d, (v - K[1, 2]) / K[1, 1] * d, d], axis=-1)
    valid = d > 0
    cos_max = np.cos(np.deg2rad(max_angle_deg))
    norm_p = np.linalg.norm(P, axis=-1)
    mask = np.zeros((h, w), dtype=bool)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        Q = np.roll(P, shift=(-dy, -dx), axis=(0, 1))
        qv = np.roll(valid, shift=(-dy, -dx), axis=(0, 1))
        # neighbours that wrapped around the border do not count
        if dy == 1:
            qv[-1, :] = False
        if dy == -1:
            qv[0, :] = False
        if dx == 1:
            qv[:, -1] = False
        if dx == -1:
            qv[:, 0] = False
        step = Q - P
        ns = np.linalg.norm(step, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.abs(np.sum(step * P, axis=-1)) / (ns * norm_p)
        mask |= valid & qv & (ns > 0) & (c > cos_max)
    return mask


def shadow_veil_filter(depth: np.ndarray, K: np.ndarray, baseline: float = 0.08,
                       max_angle_deg: float = 10.0) -> np.ndarray:
    """Depth with shadow and veil pixels removed (set to 0)."""
    d = np.asarray(depth, dtype=np.float32).copy()
    d[shadow_mask(d, K, baseline) | veil_mask(d, K, max_angle_deg)] = 0
    return d


@njit(cache=True, parallel=True)
def _fill_gaps_pass(d, max_gap, max_rel_step):
    h, w = d.shape
    out = d.copy()
    filled = 0
    for v in prange(h):
        for u in range(w):
            if d[v, u] > 0.0:
                continue
            best_gap = max_gap + 1
            best = 0.0
            for axis in range(2):
                # nearest valid reading on each side along the row (axis 0) or the column (axis 1)
                du = 1 - axis
                dv = axis
                a = 0.0
                ga = 0
                b = 0.0
                gb = 0
                for s in range(1, max_gap + 1):
                    uu = u - s * du
                    vv = v - s * dv
                    if uu < 0 or vv < 0:
                        break
                    if d[vv, uu] > 0.0:
                        a = d[vv, uu]
                        ga = s
                        break
                for s in range(1, max_gap + 1):
                    uu = u + s * du
                    vv = v + s * dv
                    if uu >= w or vv >= h:
                        break
                    if d[vv, uu] > 0.0:
                        b = d[vv, uu]
                        gb = s
                        break
                if ga == 0 or gb == 0 or ga + gb - 1 > max_gap:
                    continue
                if abs(a - b) > max_rel_step * min(a, b):
                    continue  # a depth edge: do not bridge it
                if ga + gb - 1 < best_gap:
                    best_gap = ga + gb - 1
                    best = a + (b - a) * ga / (ga + gb)
            if best > 0.0:
                out[v, u] = best
    for v in range(h):
        for u in range(w):
            if out[v, u] > 0.0 and not d[v, u] > 0.0:
                filled += 1
    return out, filled


def fill_gaps(depth: np.ndarray, max_gap: int = 2, max_rel_step: float = 0.03) -> tuple[np.ndarray, int]:
    """Fill invalid runs of at most `max_gap` pixels along a row or a column that lie between two readings
    within `max_rel_step` (relative) of each other, by linear interpolation; returns (depth, pixels filled).

    Why: some sensors (e.g. RealSense depth registered to a larger colour image) leave whole rows and columns
    without a reading every few pixels. A voxel takes the reading of the one pixel its centre projects onto,
    so such lines leave speckles of unknown voxels inside observed surfaces: holes in the mesh, no TSDF
    normals for ICP, and false information gain for next-best view. Depth edges are never bridged (the two
    readings must agree), so blobs of no reading (shadows, glass, out of range) stay invalid. Two passes:
    the second fills the crossings of invalid rows and columns from the first pass's values.
    """
    max_gap = int(max_gap)
    if max_gap < 0:
        raise ConfigError(f"expected a gap width >= 0 pixels, got {max_gap}", parameter="max_gap")
    d = np.asarray(depth, dtype=np.float32)
    if max_gap == 0:
        return d, 0
    total = 0
    for _ in range(2):
        d, n = _fill_gaps_pass(d, max_gap, float(max_rel_step))
        total += n
        if n == 0:
            break
    return d, int(total)
