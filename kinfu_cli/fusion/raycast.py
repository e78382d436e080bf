"""The model surface seen from a pose, ray cast from a TernaryVolume: the target of frame-to-model ICP.

model_cloud: the whole ray (kernels.raycast_kernel via TernaryVolume.raycast) as an open3d cloud, the target
of open3d's ICP. band_raycast: the tracker's fast cast. A tracked frame's depth tells where along each ray the
surface is to within the pose error, so the march covers only a band of +-margin around that depth instead of
the whole min_depth..max_depth range: tens of steps per ray instead of hundreds, which is what makes a model map
per frame affordable (KinFu casts the whole ray on a GPU). Pixels without a depth reading get no model point;
projective ICP and the agreement check only look at pixels that have one.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from kinfu_cli.core.camera import scaled_intrinsics
from kinfu_cli.fusion import kernels as kn

# band_raycast states per pixel
BAND_NONE = 0  # no reading, or no known surface in the band
BAND_HIT = 1  # a zero crossing in the band: depth, vertex (and normal where the TSDF gradient is known)
BAND_OCCLUDED = 2  # the band starts behind a model surface (the model sees something nearer than the reading)


def model_cloud(volume, K: np.ndarray, width: int, height: int, T_world_camera: np.ndarray, scale: float = 0.5):
    """open3d PointCloud (world) with normals of the model surface seen from a pose, ray cast at `scale` of
    the image size: the target of frame-to-model ICP."""
    w = max(8, int(round(width * scale)))
    h = max(8, int(round(height * scale)))
    _, normals, verts = volume.raycast(scaled_intrinsics(K, w / width), w, h, T_world_camera)
    return _cloud(verts, normals)


def band_cloud(volume, K: np.ndarray, T_world_camera: np.ndarray, hint: np.ndarray, margin: float,
               start: float | None = None):
    """model_cloud cast only within +-margin (m) of hint's depths (band_raycast with TSDF normals and its `start`;
    K: hint's intrinsics): the pixels with a reading, each ray a band instead of the whole depth range."""
    _, verts, normals, _ = band_raycast(volume, K, T_world_camera, hint, margin, start=start)
    return _cloud(verts, normals)


def _cloud(verts: np.ndarray, normals: np.ndarray):
    """open3d PointCloud of the pixels with both a vertex and a normal."""
    import open3d as o3d  # heavy: only when tracking

    ok = np.isfinite(verts[..., 0]) & np.isfinite(normals[..., 0])
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(verts[ok].astype(np.float64))
    pc.normals = o3d.utility.Vector3dVector(normals[ok].astype(np.float64))
    return pc


def band_raycast(volume, K: np.ndarray, T_world_camera: np.ndarray, hint: np.ndarray, margin: float,
                 tsdf_normals: bool = True, start: float | None = None):
    """Ray cast of the model from a pose, per pixel only within +-margin (m, along z) of hint's depth.

    hint: (H, W) depth (m, 0 = none) whose pixels are the rays (K is its intrinsics). Returns depth (H, W)
    float32 (0 = none), vertices and normals (H, W, 3) float32 world (NaN = none) and the state per pixel
    (BAND_NONE / BAND_HIT / BAND_OCCLUDED). tsdf_normals False: no normals (NaN), six trilinear TSDF samples
    per pixel saved (the tracker takes them from the vertex map).
    start (m, < margin): the march starts `start` in front of the reading when the model is known free space
    there, and steps back towards the band's near end until it is (when it never is: from the near end, as
    without `start`). Most rays then walk a few voxels instead of the whole near half of the band; what it
    can miss is a surface lying wholly (front, back and free space behind it) between the band's near end and
    the start: a sheet thinner than the truncation distance seen from both sides.
    """
    K = np.asarray(K, dtype=np.float64)
    T = np.asarray(T_world_camera, dtype=np.float64)
    return _band_kernel(np.array(volume.shape, dtype=np.int64), volume.block_idx, volume.block_w, volume.pool_v,
                        volume.pool_w, np.asarray(volume.origin, dtype=np.float64), float(volume.voxel_size),
                        float(volume.truncation), T, np.linalg.inv(K), np.ascontiguousarray(hint, dtype=np.float32),
                        float(margin), float(margin if start is None else min(start, margin)),
                        float(volume.min_depth), float(volume.max_depth), bool(tsdf_normals))


@njit(cache=True, inline="always")
def _march_start(block_idx, block_w, pool_v, pool_w, dims, origin, inv_vs, o, d, t0, ts, back):
    """The ray parameter to march from: ts, or the first point stepping back from it by `back` where the model is
    known free space (v > 0), t0 when none is after t0 (band_raycast's `start`)."""
    t = ts
    while t > t0:
        gx = int(math.floor((o[0] + d[0] * t - origin[0]) * inv_vs))
        gy = int(math.floor((o[1] + d[1] * t - origin[1]) * inv_vs))
        gz = int(math.floor((o[2] + d[2] * t - origin[2]) * inv_vs))
        v, known = kn._corner(block_idx, block_w, pool_v, pool_w, dims, gx, gy, gz)
        if known and v > 0.0:
            return t
        t -= back
    return t0


@njit(cache=True)
def _slab(o, d, lo, hi, t0, t1):
    """The ray parameters [t0, t1] clipped to the slab lo..hi of one axis (t1 < t0: misses it)."""
    if abs(d) < 1e-12:
        return (t0, -1.0) if (o < lo or o > hi) else (t0, t1)
    ta = (lo - o) / d
    tb = (hi - o) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@njit(cache=True, parallel=True, error_model="numpy")
def _band_kernel(dims, block_idx, block_w, pool_v, pool_w, origin, vs, trunc, T_wc, Kinv, hint, margin,
                 start, min_depth, max_depth, with_normals):
    """Per pixel with a hint: the first + to - zero crossing within the band (kernels.raycast_kernel's march,
    restricted to the band; a band whose first known sample is inside a surface is BAND_OCCLUDED)."""
    height, width = hint.shape
    depth = np.zeros((height, width), dtype=np.float32)
    verts = np.full((height, width, 3), np.nan, dtype=np.float32)
    norms = np.full((height, width, 3), np.nan, dtype=np.float32)
    state = np.zeros((height, width), dtype=np.int8)
    o = (T_wc[0, 3], T_wc[1, 3], T_wc[2, 3])
    inv_vs = 1.0 / vs
    blk = kn.B * vs
    for pv in prange(height):
        for pu in range(width):
            zh = hint[pv, pu]
            if not zh > 0.0:
                continue
            xc = Kinv[0, 0] * pu + Kinv[0, 1] * pv + Kinv[0, 2]
            yc = Kinv[1, 0] * pu + Kinv[1, 1] * pv + Kinv[1, 2]
            nrm = math.sqrt(xc * xc + yc * yc + 1.0)
            d = (T_wc[0, 0] * xc + T_wc[0, 1] * yc + T_wc[0, 2]) / nrm, \
                (T_wc[1, 0] * xc + T_wc[1, 1] * yc + T_wc[1, 2]) / nrm, \
                (T_wc[2, 0] * xc + T_wc[2, 1] * yc + T_wc[2, 2]) / nrm
            t0 = max(min_depth, zh - margin) * nrm
            t1 = min(max_depth, zh + margin) * nrm
            for a in range(3):  # clip to the grid box
                t0, t1 = _slab(o[a], d[a], origin[a], origin[a] + dims[a] * vs, t0, t1)
            t = _march_start(block_idx, block_w, pool_v, pool_w, dims, origin, inv_vs, o, d, t0,
                             min(t1, (zh - start) * nrm), 0.8 * trunc)
            prev_v = 0.0
            prev_t = t0
            prev_known = False
            seen_known = False
            while t < t1:
                px = o[0] + d[0] * t
                py = o[1] + d[1] * t
                pz = o[2] + d[2] * t
                gx = int((px - origin[0]) * inv_vs)
                gy = int((py - origin[1]) * inv_vs)
                gz = int((pz - origin[2]) * inv_vs)
                if gx < 0 or gy < 0 or gz < 0 or gx >= dims[0] or gy >= dims[1] or gz >= dims[2]:
                    t += 0.5 * vs
                    continue
                i = block_idx[gx >> 3, gy >> 3, gz >> 3]
                if i < 0:  # a uniform block: unknown or known empty; jump to its exit
                    bw = block_w[gx >> 3, gy >> 3, gz >> 3]
                    prev_known = bw != 0
                    seen_known = seen_known or prev_known
                    prev_v = 1.0
                    prev_t = t
                    tex = t1
                    g3 = (gx >> 3, gy >> 3, gz >> 3)
                    for a in range(3):
                        if d[a] > 1e-12:
                            tex = min(tex, (origin[a] + (g3[a] + 1) * blk - o[a]) / d[a])
                        elif d[a] < -1e-12:
                            tex = min(tex, (origin[a] + g3[a] * blk - o[a]) / d[a])
                    t = max(tex + 1e-5, t + 0.25 * vs)
                    continue
                k = (gx & 7) * 64 + (gy & 7) * 8 + (gz & 7)
                w = pool_w[i, k]
                v = pool_v[i, k] / kn.V_SCALE
                if w == 0:
                    prev_known = False
                    prev_t = t
                    t += 0.5 * vs
                    continue
                if v <= 0.0:
                    if not seen_known:
                        state[pv, pu] = BAND_OCCLUDED
                        break
                    th = t
                    if prev_known and prev_v > 0.0:
                        a0, oka = kn._trilinear(block_idx, block_w, pool_v, pool_w, dims,
                                                (o[0] + d[0] * prev_t - origin[0]) * inv_vs - 0.5,
                                                (o[1] + d[1] * prev_t - origin[1]) * inv_vs - 0.5,
                                                (o[2] + d[2] * prev_t - origin[2]) * inv_vs - 0.5)
                        c0, okc = kn._trilinear(block_idx, block_w, pool_v, pool_w, dims,
                                                (px - origin[0]) * inv_vs - 0.5, (py - origin[1]) * inv_vs - 0.5,
                                                (pz - origin[2]) * inv_vs - 0.5)
                        if oka and okc and a0 > c0:
                            # the crossing of the trilinear TSDF, interpolated or (when the nearest voxels' sign
                            # change and the trilinear one disagree, half the rays) extrapolated by up to a voxel
                            th = min(max(prev_t + (t - prev_t) * a0 / (a0 - c0), prev_t - vs), t + vs)
                        else:
                            th = prev_t + (t - prev_t) * prev_v / (prev_v - v)
                    hx = o[0] + d[0] * th
                    hy = o[1] + d[1] * th
                    hz = o[2] + d[2] * th
                    depth[pv, pu] = th / nrm
                    verts[pv, pu, 0] = hx
                    verts[pv, pu, 1] = hy
                    verts[pv, pu, 2] = hz
                    state[pv, pu] = BAND_HIT
                    if not with_normals:
                        break
                    nx, ny, nz, ok = kn._normal(block_idx, block_w, pool_v, pool_w, dims,
                                                (hx - origin[0]) * inv_vs - 0.5, (hy - origin[1]) * inv_vs - 0.5,
                                                (hz - origin[2]) * inv_vs - 0.5, d[0], d[1], d[2])
                    if ok:
                        norms[pv, pu, 0] = nx
                        norms[pv, pu, 1] = ny
                        norms[pv, pu, 2] = nz
                    break
                prev_known = True
                seen_known = True
                prev_v = v
                prev_t = t
                t += max(0.5 * vs, 0.8 * v * trunc)
    return depth, verts, norms, state
