"""The straightforward reference ray marcher (the paper's NBV-CPU-step baseline), for tests and the benchmark.

Every pixel of every view is marched from the sensor in fixed steps of half a voxel (one thread, no
empty-space skipping, no sharing between views), and each sample looks up the voxel it falls in. The
semantics are those of `raycast.py` (same knowledge-map classes and gain terms), so per-view gains of
the fast path must agree with it; they differ only where a half-voxel step skips the corner of a voxel
(or where shared roll rays round to a neighbouring pixel).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from kinfu_cli.nbv.raycast import CLS_EMPTY_EXIT, CLS_OCCUPIED, CLS_UNKNOWN, N_TERMS, RayVolume


@njit(cache=True)
def _march(labels, lo, vs, p, d, min_range, max_range, cen, r2, through, optimistic, p_unknown, h_unknown, vals,
           step):
    n0, n1, n2 = labels.shape
    t0 = 0.0
    t1 = max_range
    dims = (n0, n1, n2)
    for a in range(3):
        hi = lo[a] + dims[a] * vs
        if abs(d[a]) < 1e-12:
            if p[a] < lo[a] or p[a] > hi:
                return CLS_EMPTY_EXIT
        else:
            ta = (lo[a] - p[a]) / d[a]
            tb = (hi - p[a]) / d[a]
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
    h = step * vs
    cls = CLS_EMPTY_EXIT
    vis = 1.0
    prev_unknown_in_s = False
    pi, pj, pk = -1, -1, -1
    t = t0
    while t < t1:
        i = min(max(int(math.floor((p[0] + t * d[0] - lo[0]) / vs)), 0), n0 - 1)
        j = min(max(int(math.floor((p[1] + t * d[1] - lo[1]) / vs)), 0), n1 - 1)
        k = min(max(int(math.floor((p[2] + t * d[2] - lo[2]) / vs)), 0), n2 - 1)
        if i != pi or j != pj or k != pk:
            pi, pj, pk = i, j, k
            lab = labels[i, j, k]
            in_s = False
            dist2 = 0.0
            if lab != -1 and t >= min_range:
                cx = lo[0] + (i + 0.5) * vs - cen[0]
                cy = lo[1] + (j + 0.5) * vs - cen[1]
                cz = lo[2] + (k + 0.5) * vs - cen[2]
                dist2 = cx * cx + cy * cy + cz * cz
                in_s = dist2 <= r2
            if optimistic and lab == 0 and not in_s:
                lab = -1
            if lab == -1:
                prev_unknown_in_s = False
            else:
                if cls == CLS_EMPTY_EXIT:
                    if lab == 0:
                        cls = CLS_UNKNOWN
                        if in_s:
                            vals[0] = 1.0
                            vals[1] = 1.0 / (t * t)
                    else:
                        cls = CLS_OCCUPIED
                    if not through:
                        return cls
                if lab == 0:
                    if in_s:
                        vals[3] += vis * h_unknown
                    vis *= 1.0 - p_unknown
                    prev_unknown_in_s = in_s
                    if vis < 1e-7:
                        return cls
                else:
                    if prev_unknown_in_s:
                        vals[2] = 1.0
                    return cls
        t += h
    return cls


@njit(cache=True)
def _reference_view(labels, lo, vs, R, o, fx, fy, cx, cy, W, H, min_range, max_range, cen, radius, through,
                    optimistic, p_unknown, step, counts, terms):
    r2 = radius * radius
    h = 0.0
    if 0.0 < p_unknown < 1.0:
        h = -(p_unknown * math.log2(p_unknown) + (1 - p_unknown) * math.log2(1 - p_unknown))
    vals = np.zeros(N_TERMS)
    d = np.empty(3)
    for v in range(H):
        for u in range(W):
            x = (u - cx) / fx
            y = (v - cy) / fy
            nrm = math.sqrt(x * x + y * y + 1.0)
            for a in range(3):
                d[a] = (R[a, 0] * x + R[a, 1] * y + R[a, 2]) / nrm
            for a in range(N_TERMS):
                vals[a] = 0.0
            c = _march(labels, lo, vs, o, d, min_range, max_range, cen, r2, through, optimistic, p_unknown, h, vals,
                       step)
            counts[c] += 1
            for a in range(N_TERMS):
                terms[a] += vals[a]


def reference_views(vol: RayVolume, poses: np.ndarray, camera, center, radius: float, *, through: bool = False,
                    optimistic: bool = False, p_unknown: float = 0.5,
                    step: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Full-image fixed-step marching of each view: counts (V, 3) unknown/occupied/empty-exit over all
    pixels and summed gain terms (V, 4), as `raycast.cast_views` returns them. `step` is the marching step
    in voxels (half a voxel, the paper's NBV-CPU-step; smaller steps converge to exact traversal)."""
    cam = camera.widened()
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    counts = np.zeros((poses.shape[0], 3), np.int64)
    terms = np.zeros((poses.shape[0], N_TERMS), np.float64)
    cen = np.asarray(center, dtype=np.float64).reshape(3)
    for i, T in enumerate(poses):
        _reference_view(vol.labels, vol.origin, vol.voxel_size, np.ascontiguousarray(T[:3, :3]),
                        np.ascontiguousarray(T[:3, 3]), cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height,
                        cam.min_range, min(cam.max_range, 1e30), cen, float(radius), bool(through),
                        bool(optimistic), float(p_unknown), float(step), counts[i], terms[i])
    return counts, terms
