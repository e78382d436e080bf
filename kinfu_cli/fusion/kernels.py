"""numba kernels behind TernaryVolume: block classification, integration, labels, ray casting.

Storage (see volume.py): the grid is cut into 8x8x8 blocks. `block_idx[bx, by, bz]` is -1 for a block
without voxel storage, else a row of the pools. A block without storage is uniform: `block_w == 0`
means unknown (v = 0, w = 0), `block_w > 0` means every voxel is known-empty with v = 1 and w = block_w.
Free space carved far in front of the surface therefore costs one byte per 512 voxels; only blocks
near a surface, at the frustum border or next to invalid pixels get per-voxel storage.

Pools: `pool_v` int16 (n, 512) holding v * V_SCALE, `pool_w` uint8 (n, 512), `pool_c` uint8 (n, 512, 3)
(or (0, 512, 3) without colour). Voxel (lx, ly, lz) of a block is entry lx * 64 + ly * 8 + lz.

Integration follows the projective voxel-centric rule (digest §1.2 eqs. 2.1-2.3, as open3d's
UniformTSDFVolume): a voxel centre projecting onto pixel (u, v) with valid depth d gets
sdf = (d - z) * |K^-1 (u, v, 1)| and, when sdf > -truncation, v' = (v w + min(1, sdf / trunc)) / (w + 1),
w' = min(w + 1, max_weight).

Per frame: classify_blocks sorts the blocks of the frustum into SKIP (behind every reading or outside the
image), CARVE (more than the truncation in front of every valid reading under it: tsdf = 1 for all voxels,
a weight step for a uniform block) and VOXEL; VOXEL blocks get storage and the per-voxel rule, written as
flat branch-free loops over the block's 512 voxels that LLVM vectorises (_update_block).
"""

from __future__ import annotations

import math


import numpy as np
from numba import njit, prange

from kinfu_cli.fusion.color_mode import mode_update

B = 8  # block edge in voxels
B3 = B * B * B
V_SCALE = 32767.0

SKIP = 0
CARVE = 1
VOXEL = 2
CARVE_VALID = 3  # _classify_box only: in free space, but some pixels under it have no reading (-> VOXEL)


@njit(cache=True)
def _invalid_integral(depth):
    """Summed-area table of invalid (d <= 0) pixels, shape (H + 1, W + 1)."""
    h, w = depth.shape
    s = np.zeros((h + 1, w + 1), dtype=np.int32)
    for v in range(h):
        row = 0
        for u in range(w):
            if not depth[v, u] > 0.0:
                row += 1
            s[v + 1, u + 1] = s[v, u + 1] + row
    return s


PYR_LEVELS = 5  # min/max squares of 1, 2, 4, 8, 16 pixels


@njit(cache=True, parallel=True)
def depth_pyramid(depth, pm):
    """Sparse table of valid depth: pm[k, v, u, 0] / pm[k, v, u, 1] = min / max valid depth over the pixel
    square [v, v + 2^k) x [u, u + 2^k) (clipped to the image); inf / 0 where it holds no valid pixel. Any
    pixel rectangle's exact min / max then costs a few look-ups (overlapping squares), see _range_minmax.
    Min and max sit side by side so that one look-up touches one cache line. Written into pm, an array of
    shape (levels, H, W, 2) float32 (reused from frame to frame: no fresh pages to fault in)."""
    h, w = depth.shape
    levels = pm.shape[0]
    for v in prange(h):
        for u in range(w):
            d = depth[v, u]
            if d > 0.0:
                pm[0, v, u, 0] = d
                pm[0, v, u, 1] = d
            else:
                pm[0, v, u, 0] = np.inf
                pm[0, v, u, 1] = 0.0
    for k in range(1, levels):
        s = 1 << (k - 1)
        for v in prange(h):
            v2 = min(v + s, h - 1)
            for u in range(w):
                u2 = min(u + s, w - 1)
                pm[k, v, u, 0] = min(min(pm[k - 1, v, u, 0], pm[k - 1, v, u2, 0]),
                                     min(pm[k - 1, v2, u, 0], pm[k - 1, v2, u2, 0]))
                pm[k, v, u, 1] = max(max(pm[k - 1, v, u, 1], pm[k - 1, v, u2, 1]),
                                     max(pm[k - 1, v2, u, 1], pm[k - 1, v2, u2, 1]))
    return pm


@njit(cache=True)
def _range_minmax(pm, u0, u1, v0, v1):
    """Exact min / max valid depth over pixels [u0, u1] x [v0, v1] (inclusive, inside the image)."""
    side = min(u1 - u0 + 1, v1 - v0 + 1)
    k = 0
    while k + 1 < pm.shape[0] and (2 << k) <= side:
        k += 1
    s = 1 << k
    dmin = np.inf
    dmax = 0.0
    y = v0
    while True:
        yy = min(y, v1 + 1 - s)
        x = u0
        while True:
            xx = min(x, u1 + 1 - s)
            a = pm[k, yy, xx, 0]
            if a < dmin:
                dmin = a
            b2 = pm[k, yy, xx, 1]
            if b2 > dmax:
                dmax = b2
            if xx + s > u1:
                break
            x += s
        if yy + s > v1:
            break
        y += s
    return dmin, dmax


@njit(cache=True, error_model="numpy")
def _classify_box(lo0, lo1, lo2, n, vs, T_cw, fx, fy, cx, cy, width, height, trunc, pm, inv_sat):
    """SKIP / CARVE / VOXEL for the n^3 voxels whose centres start at (lo0, lo1, lo2).

    Conservative: CARVE and SKIP are returned only when every voxel would get exactly that from the
    per-voxel rule; anything uncertain is VOXEL.
    """
    ext = (n - 1) * vs
    zmin = np.inf
    zmax = -np.inf
    umin = np.inf
    umax = -np.inf
    vmin = np.inf
    vmax = -np.inf
    behind = False
    for c in range(8):
        px = lo0 + ext * (c & 1)
        py = lo1 + ext * ((c >> 1) & 1)
        pz = lo2 + ext * ((c >> 2) & 1)
        xc = T_cw[0, 0] * px + T_cw[0, 1] * py + T_cw[0, 2] * pz + T_cw[0, 3]
        yc = T_cw[1, 0] * px + T_cw[1, 1] * py + T_cw[1, 2] * pz + T_cw[1, 3]
        zc = T_cw[2, 0] * px + T_cw[2, 1] * py + T_cw[2, 2] * pz + T_cw[2, 3]
        zmin = min(zmin, zc)
        zmax = max(zmax, zc)
        if zc <= 0.0:
            behind = True
        else:
            uf = xc * fx / zc + cx + 0.5
            vf = yc * fy / zc + cy + 0.5
            umin = min(umin, uf)
            umax = max(umax, uf)
            vmin = min(vmin, vf)
            vmax = max(vmax, vf)
    if zmax <= 0.0:
        return SKIP  # entirely behind the camera
    if behind:
        return VOXEL  # straddles the camera plane: exact per-voxel rule
    if umax < 0.0001 or vmax < 0.0001 or umin >= width - 0.0001 or vmin >= height - 0.0001:
        return SKIP  # outside the image
    inside = umin >= 0.0001 and vmin >= 0.0001 and umax < width - 0.0001 and vmax < height - 0.0001
    u0 = max(int(umin), 0)
    u1 = min(int(umax), width - 1)
    v0 = max(int(vmin), 0)
    v1 = min(int(vmax), height - 1)
    dmin, dmax = _range_minmax(pm, u0, u1, v0, v1)
    if dmax <= 0.0:
        return SKIP  # no valid depth under the box
    if zmin >= dmax + trunc:
        return SKIP  # entirely beyond the truncation band behind every observed point
    if dmin - zmax >= trunc:
        if not inside:
            return CARVE_VALID  # partly outside the image: carve the voxels that land on a valid pixel
        ninv = inv_sat[v1 + 1, u1 + 1] - inv_sat[v0, u1 + 1] - inv_sat[v1 + 1, u0] + inv_sat[v0, u0]
        return CARVE if ninv == 0 else CARVE_VALID
    return VOXEL


SUPER = 4  # classify_blocks looks at 4^3-block super-blocks first
MID = 2  # then at the 2^3-block cubes of a super-block that is neither SKIP nor CARVE
MID_PER_SUPER = (SUPER // MID) ** 3


@njit(cache=True, error_model="numpy")
def _box_class(bx, by, bz, nblk, origin, vs, T_cw, fx, fy, cx, cy, width, height, trunc, pm, inv_sat,
               planes, far):
    """_classify_box for the cube of nblk^3 blocks starting at block (bx, by, bz), after a cheap bounding-sphere
    test against the frustum's side planes and depth range (planes: (4, 3) rows a, c, norm with a point
    inside when (a x_c + c z_c) / norm >= -radius)."""
    n = nblk * B
    lo0 = origin[0] + (bx * B + 0.5) * vs
    lo1 = origin[1] + (by * B + 0.5) * vs
    lo2 = origin[2] + (bz * B + 0.5) * vs
    half = 0.5 * (n - 1) * vs
    rad = half * math.sqrt(3.0) + vs
    px = lo0 + half
    py = lo1 + half
    pz = lo2 + half
    xc = T_cw[0, 0] * px + T_cw[0, 1] * py + T_cw[0, 2] * pz + T_cw[0, 3]
    yc = T_cw[1, 0] * px + T_cw[1, 1] * py + T_cw[1, 2] * pz + T_cw[1, 3]
    zc = T_cw[2, 0] * px + T_cw[2, 1] * py + T_cw[2, 2] * pz + T_cw[2, 3]
    if zc + rad <= 0.0 or zc - rad > far:
        return SKIP
    for q in range(4):
        s = xc if q < 2 else yc
        if (planes[q, 0] * s + planes[q, 1] * zc) / planes[q, 2] < -rad:
            return SKIP
    return _classify_box(lo0, lo1, lo2, n, vs, T_cw, fx, fy, cx, cy, width, height, trunc, pm, inv_sat)


@njit(cache=True, parallel=True, error_model="numpy")
def classify_blocks(nb, origin, vs, T_cw, fx, fy, cx, cy, width, height,
                    trunc, pm, inv_sat, dmax_all, b_lo, b_hi):
    """Class per block (flattened x-major): SKIP, CARVE (all voxels get tsdf = 1) or VOXEL (per-voxel).

    Only blocks in [b_lo, b_hi) (the viewing frustum's bounding box, in blocks) are looked at, a super-block of
    SUPER^3 blocks at a time: most super-blocks lie behind the surfaces or outside the image (SKIP) or wholly
    in free space (CARVE) and settle all their blocks with one test; the others are looked at by MID^3-block
    cubes before block by block (a cube near a surface is often wholly behind or in front of it).
    """
    nbx, nby, nbz = nb[0], nb[1], nb[2]
    cls = np.zeros(nbx * nby * nbz, dtype=np.uint8)
    s_lo = b_lo // SUPER
    rx = (b_hi[0] + SUPER - 1) // SUPER - s_lo[0]
    ry = (b_hi[1] + SUPER - 1) // SUPER - s_lo[1]
    rz = (b_hi[2] + SUPER - 1) // SUPER - s_lo[2]
    if b_hi[0] <= b_lo[0] or b_hi[1] <= b_lo[1] or b_hi[2] <= b_lo[2]:
        return cls
    # frustum side planes (left, right: x; top, bottom: y), one pixel outside the image
    planes = np.empty((4, 3))
    edges = ((-1.0 - cx) / fx, (width + 1.0 - cx) / fx, (-1.0 - cy) / fy, (height + 1.0 - cy) / fy)
    for q in range(4):
        sign = 1.0 if q % 2 == 0 else -1.0
        planes[q, 0] = sign
        planes[q, 1] = -sign * edges[q]
        planes[q, 2] = math.sqrt(1.0 + edges[q] * edges[q])
    far = dmax_all + trunc
    nsup = rx * ry * rz
    half = (nsup + 1) // 2
    for jj in prange(nsup):
        # even super-blocks first, then odd ones: numba gives each thread a contiguous half of the range, and
        # neighbouring super-blocks cost alike, so both halves get similar work (x-major halves differed by 20 %)
        j = 2 * jj if jj < half else 2 * (jj - half) + 1
        sx = j // (ry * rz)
        rem = j - sx * ry * rz
        sy = rem // rz
        sz = rem - sy * rz
        bx0 = (sx + s_lo[0]) * SUPER
        by0 = (sy + s_lo[1]) * SUPER
        bz0 = (sz + s_lo[2]) * SUPER
        sc = _box_class(bx0, by0, bz0, SUPER, origin, vs, T_cw, fx, fy, cx, cy, width, height, trunc, pm,
                        inv_sat, planes, far)
        if sc == SKIP:
            continue
        for m in range(MID_PER_SUPER):  # the super-block's 2^3-block cubes, then their blocks
            mx0 = bx0 + MID * (m >> 2)
            my0 = by0 + MID * ((m >> 1) & 1)
            mz0 = bz0 + MID * (m & 1)
            if sc == CARVE:
                mc = CARVE
            else:
                mc = _box_class(mx0, my0, mz0, MID, origin, vs, T_cw, fx, fy, cx, cy, width, height, trunc, pm,
                                inv_sat, planes, far)
                if mc == SKIP:
                    continue
            for bx in range(max(mx0, b_lo[0]), min(mx0 + MID, b_hi[0])):
                for by in range(max(my0, b_lo[1]), min(my0 + MID, b_hi[1])):
                    for bz in range(max(mz0, b_lo[2]), min(mz0 + MID, b_hi[2])):
                        if mc == CARVE:
                            c = CARVE
                        else:
                            c = _box_class(bx, by, bz, 1, origin, vs, T_cw, fx, fy, cx, cy, width, height, trunc,
                                           pm, inv_sat, planes, far)
                        cls[(bx * nby + by) * nbz + bz] = VOXEL if c == CARVE_VALID else c
    return cls


@njit(cache=True)
def work_list(cls, block_idx_flat):
    """One pass over the classes: the blocks with work (CARVE or VOXEL) and the VOXEL blocks that lack storage,
    both in block order, and the counts of CARVE and VOXEL blocks."""
    n = 0
    n_new = 0
    n_carve = 0
    for b in range(cls.shape[0]):
        c = cls[b]
        if c != SKIP:
            n += 1
            if c == CARVE:
                n_carve += 1
            elif block_idx_flat[b] < 0:
                n_new += 1
    work = np.empty(n, dtype=np.int64)
    new_b = np.empty(n_new, dtype=np.int64)
    j = 0
    m = 0
    for b in range(cls.shape[0]):
        c = cls[b]
        if c != SKIP:
            work[j] = b
            j += 1
            if c == VOXEL and block_idx_flat[b] < 0:
                new_b[m] = b
                m += 1
    return work, new_b, n_carve, n - n_carve


@njit(cache=True, parallel=True)
def clean_depth(depth, min_depth, max_depth):
    """float32 copy of depth with readings outside [min_depth, max_depth] (and NaN, inf) set to 0, in one pass."""
    h, w = depth.shape
    out = np.empty((h, w), dtype=np.float32)
    lo = np.float32(min_depth)  # compared in float32, as numpy compares a float32 image with a Python float
    hi = np.float32(max_depth)
    for v in prange(h):
        for u in range(w):
            d = np.float32(depth[v, u])
            out[v, u] = d if (np.isfinite(d) and d >= lo and d <= hi) else np.float32(0.0)
    return out


@njit(cache=True, parallel=True)
def readings_in_box(depth, T_wc, fx, fy, cx, cy, lo, hi):
    """(valid readings, readings whose point lies in the world box [lo, hi)) of a depth image seen from T_wc:
    how much of what a frame measured lands in the grid (a wrong pose puts all of it elsewhere)."""
    h, w = depth.shape
    valid = np.zeros(h, dtype=np.int64)
    inside = np.zeros(h, dtype=np.int64)
    for v in prange(h):
        yn = (v - cy) / fy
        nv = 0
        ni = 0
        for u in range(w):
            d = depth[v, u]
            if not d > 0.0:
                continue
            nv += 1
            x = (u - cx) / fx * d
            y = yn * d
            px = T_wc[0, 0] * x + T_wc[0, 1] * y + T_wc[0, 2] * d + T_wc[0, 3]
            py = T_wc[1, 0] * x + T_wc[1, 1] * y + T_wc[1, 2] * d + T_wc[1, 3]
            pz = T_wc[2, 0] * x + T_wc[2, 1] * y + T_wc[2, 2] * d + T_wc[2, 3]
            if lo[0] <= px < hi[0] and lo[1] <= py < hi[1] and lo[2] <= pz < hi[2]:
                ni += 1
        valid[v] = nv
        inside[v] = ni
    return valid.sum(), inside.sum()


def allocate_blocks(cls, block_idx_flat, block_w_flat, pool_v, pool_w, pool_c, n_used):
    """Give per-voxel storage to VOXEL blocks that lack it (see allocate_new); returns the new row count."""
    new_b = np.flatnonzero((cls == VOXEL) & (block_idx_flat < 0))
    return allocate_new(new_b, block_idx_flat, block_w_flat, pool_v, pool_w, pool_c, n_used)


@njit(cache=True, parallel=True)
def allocate_new(new_b, block_idx_flat, block_w_flat, pool_v, pool_w, pool_c, n_used):
    """Rows n_used, n_used + 1, ... for the blocks new_b (in that order), filled in parallel from their uniform
    state (the first frame fills tens of thousands); returns the new row count."""
    has_color = pool_c.shape[0] > 0
    n_new = new_b.shape[0]
    for j in range(n_new):
        block_idx_flat[new_b[j]] = n_used + j
    for j in prange(n_new):
        i = n_used + j
        bw = block_w_flat[new_b[j]]
        fill = np.int16(V_SCALE) if bw > 0 else np.int16(0)
        for k in range(B3):
            pool_v[i, k] = fill
            pool_w[i, k] = bw
            if has_color:
                pool_c[i, k, 0] = 0
                pool_c[i, k, 1] = 0
                pool_c[i, k, 2] = 0
    return n_used + n_new


@njit(cache=True, error_model="numpy")
def _carve_voxels(pool_v, pool_w, i, mw):
    """tsdf = 1 update of all voxels of pool row i (a block known to lie in free space)."""
    half = np.float32(0.5)
    scale = np.float32(V_SCALE)
    for k in range(B3):
        w0 = np.int32(pool_w[i, k])
        v0 = np.float32(pool_v[i, k])
        pool_v[i, k] = np.int16(np.floor((v0 * np.float32(w0) + scale) / np.float32(w0 + 1) + half))
        pool_w[i, k] = np.uint8(min(w0 + 1, mw))


@njit(cache=True, error_model="numpy", inline="always")
def _mean_color(pool_c, pool_w, i, k, color_f, p):
    """The running mean colour of voxel k of block i with pixel p's sample."""
    one = np.float32(1.0)
    # black = never coloured: take the sample, else a running mean that forgets slowly
    fresh = pool_c[i, k, 0] == 0 and pool_c[i, k, 1] == 0 and pool_c[i, k, 2] == 0
    alpha = one if fresh else max(one / np.float32(pool_w[i, k]), np.float32(0.1))
    for ch in range(3):
        c0 = np.float32(pool_c[i, k, ch])
        cn = np.float32(color_f[p, ch])
        pool_c[i, k, ch] = np.uint8(min(np.float32(255.0), c0 + alpha * (cn - c0) + np.float32(0.5)))


@njit(cache=True, error_model="numpy")
def _update_block(pool_v, pool_w, pool_c, pool_hc, pool_hn, i, p0, ex, ey, ez, nx, ny, nz, fx, fy, cx, cy, width,
                  height, depth_rl, color_f, color_ok, has_color, trunc, mw, color_band, mode_thr2, pix, zz, sdf,
                  depth_e, guide_band):
    """Projective update of every voxel of stored block i, as three flat loops over its 512 voxels.

    p0: camera-frame position of voxel (0, 0, 0); ex / ey / ez: camera-frame step per local x / y / z; nx, ny,
    nz: voxels of the block inside the grid. depth_rl: per pixel (depth, ray length) with depth -inf where
    there is no reading, so one comparison (sdf > -trunc) rejects invalid pixels too. The projection and the
    update loops have no branches and LLVM vectorises them; only the pixel look-up in between is scalar
    (gathers are slower than scalar loads on current x86). error_model="numpy": 1 / z is not checked for
    zero (a voxel at z = 0 fails the z > 0 test anyway), which is what lets the loops vectorise.
    With colour hypotheses (pool_hc / pool_hn not None: the mode filter, see color_mode.py) the colour goes to
    mode_update instead of the running mean, and only when the voxel is within the colour band of the guided depth
    depth_e too (guide_band wide, in units of the truncation; see guided_depth.py; empty: no such gate); a gated
    sample goes to the running mean in pool_c, which only a voxel without hypotheses shows. color_ok: per
    pixel 1 where the colour image has a sample (empty: everywhere), e.g. not where a colour camera beside the
    depth camera does not see the point.
    """
    one = np.float32(1.0)
    half = np.float32(0.5)
    zero = np.float32(0.0)
    scale = np.float32(V_SCALE)
    lo = np.float32(0.0001)
    wlim = np.float32(width) - lo
    hlim = np.float32(height) - lo
    w32 = np.int32(width)
    nx32 = np.int32(nx)
    ny32 = np.int32(ny)
    nz32 = np.int32(nz)
    for k in range(B3):
        k32 = np.int32(k)
        ix = k32 >> np.int32(6)
        iy = (k32 >> np.int32(3)) & np.int32(7)
        iz = k32 & np.int32(7)
        lx = np.float32(ix)
        ly = np.float32(iy)
        lz = np.float32(iz)
        xc = p0[0] + lx * ex[0] + ly * ey[0] + lz * ez[0]
        yc = p0[1] + lx * ex[1] + ly * ey[1] + lz * ez[1]
        zc = p0[2] + lx * ex[2] + ly * ey[2] + lz * ez[2]
        rz = one / zc
        uf = xc * fx * rz + cx + half
        vf = yc * fy * rz + cy + half
        ok = ((zc > zero) & (uf >= lo) & (uf < wlim) & (vf >= lo) & (vf < hlim)
              & (ix < nx32) & (iy < ny32) & (iz < nz32))
        p = np.int32(vf) * w32 + np.int32(uf)
        pix[k] = p if ok else np.int32(-1)
        zz[k] = zc
    for k in range(B3):
        p = pix[k]
        sdf[k] = (depth_rl[p, 0] - zz[k]) * depth_rl[p, 1] if p >= 0 else -np.inf
    ntrunc = np.float32(-trunc)
    inv_trunc = np.float32(1.0 / trunc)
    n_color = np.int32(0)
    i1 = np.int32(1)
    for k in range(B3):
        s = sdf[k]
        ok = s > ntrunc
        t = min(one, s * inv_trunc)
        sdf[k] = t
        vold = pool_v[i, k]
        wold = pool_w[i, k]
        w0 = np.int32(wold)
        # v' = (v w + t) / (w + 1) in int16 units (v * V_SCALE); w' = min(w + 1, M_w). Both computed for every
        # voxel and selected, so that the loop has no branch and no conditional load (it vectorises)
        vn = np.int16(np.floor((np.float32(vold) * np.float32(w0) + t * scale) / np.float32(w0 + i1) + half))
        wn = np.uint8(min(w0 + i1, mw))
        pool_v[i, k] = vn if ok else vold
        pool_w[i, k] = wn if ok else wold
        n_color += np.int32(ok & (abs(t) < color_band))
    if not (has_color and n_color > 0):
        return
    if pool_hn is not None:  # None (the mean path): numba prunes this branch at compile time
        guided = depth_e.shape[0] > 0
        for k in range(B3):
            p = pix[k]
            t = sdf[k]
            if p < 0 or not (t > -one and abs(t) < color_band) or (color_ok.shape[0] > 0 and not color_ok[p]):
                continue
            if guided and not abs((depth_e[p] - zz[k]) * depth_rl[p, 1] * inv_trunc) < guide_band:
                # the guided depth puts this pixel's colour on another surface: not a hypothesis' sample, only the
                # running mean's, the colour of a voxel that no ungated sample reached (mode_winners keeps it)
                _mean_color(pool_c, pool_w, i, k, color_f, p)
                continue
            mode_update(pool_hc, pool_hn, i, k, color_f[p, 0], color_f[p, 1], color_f[p, 2], mode_thr2)
        return
    for k in range(B3):
        p = pix[k]
        t = sdf[k]
        if p < 0 or not (t > -one and abs(t) < color_band) or (color_ok.shape[0] > 0 and not color_ok[p]):
            continue
        _mean_color(pool_c, pool_w, i, k, color_f, p)


@njit(cache=True, parallel=True)
def depth_and_raylen(depth, raylen):
    """(H * W, 2) float32: depth (-inf where there is no reading) and ray length |K^-1 (u, v, 1)| per pixel."""
    h, w = depth.shape
    out = np.empty((h * w, 2), dtype=np.float32)
    for v in prange(h):
        for u in range(w):
            d = depth[v, u]
            out[v * w + u, 0] = d if d > 0.0 else -np.inf
            out[v * w + u, 1] = raylen[v, u]
    return out


@njit(cache=True, parallel=True)
def integrate_blocks(cls, nb, dims, block_idx_flat, block_w_flat, pool_v, pool_w, pool_c, pool_hc, pool_hn,
                     origin, vs, T_cw, fx, fy, cx, cy, width, height, depth_rl, color, color_ok, trunc, max_w,
                     work, mode_thr, depth_e, guide_voxels):
    """Apply one frame: CARVE blocks in bulk (a weight step for uniform blocks, tsdf = 1 for stored ones);
    VOXEL blocks voxel by voxel (_update_block). `work` lists the blocks to visit; it is cut into one run per
    worker task, each with its own scratch rows. pool_hc / pool_hn: colour hypotheses of the mode filter (None:
    running mean, compiled without the mode code), mode_thr its colour distance threshold (RGB 0..255 units),
    depth_e the guided depth (H * W float32) that gates its colour samples: a voxel takes one as a hypothesis'
    only within guide_voxels of it too (empty: no such gate), else as the running mean's."""
    nby, nbz = nb[1], nb[2]
    has_color = pool_c.shape[0] > 0 and color.shape[0] == height * width
    mw = np.int32(max_w)
    # colour the voxels within about a voxel of the surface: marching-cubes vertices take the nearest one's
    color_band = np.float32(min(1.0, 1.2 * vs / trunc))
    mode_thr2 = np.float32(mode_thr * mode_thr)
    guide_band = np.float32(guide_voxels * vs / trunc)  # the same test against the guided depth, its own width
    ex = np.empty(3, dtype=np.float32)
    ey = np.empty(3, dtype=np.float32)
    ez = np.empty(3, dtype=np.float32)
    for r in range(3):
        ex[r] = T_cw[r, 0] * vs
        ey[r] = T_cw[r, 1] * vs
        ez[r] = T_cw[r, 2] * vs
    fx32, fy32, cx32, cy32 = np.float32(fx), np.float32(fy), np.float32(cx), np.float32(cy)
    n = work.shape[0]
    nrun = min(n, 64)
    for r in prange(nrun):
        pix = np.empty(B3, dtype=np.int32)
        zz = np.empty(B3, dtype=np.float32)
        sdf = np.empty(B3, dtype=np.float32)
        p0 = np.empty(3, dtype=np.float32)
        for j in range(r * n // nrun, (r + 1) * n // nrun):
            b = work[j]
            c = cls[b]
            if c == SKIP:
                continue
            i = block_idx_flat[b]
            if c == CARVE:
                if i < 0:
                    block_w_flat[b] = np.uint8(min(np.int32(block_w_flat[b]) + 1, mw))
                else:
                    _carve_voxels(pool_v, pool_w, i, mw)
                continue
            bx = b // (nby * nbz)
            rem = b - bx * nby * nbz
            by = rem // nbz
            bz = rem - by * nbz
            px = origin[0] + (bx * B + 0.5) * vs
            py = origin[1] + (by * B + 0.5) * vs
            pz = origin[2] + (bz * B + 0.5) * vs
            for q in range(3):
                p0[q] = np.float32(T_cw[q, 0] * px + T_cw[q, 1] * py + T_cw[q, 2] * pz + T_cw[q, 3])
            _update_block(pool_v, pool_w, pool_c, pool_hc, pool_hn, i, p0, ex, ey, ez, min(B, dims[0] - bx * B),
                          min(B, dims[1] - by * B), min(B, dims[2] - bz * B), fx32, fy32, cx32, cy32, width,
                          height, depth_rl, color, color_ok, has_color, trunc, mw, color_band, mode_thr2, pix, zz,
                          sdf, depth_e, guide_band)


@njit(cache=True, parallel=True)
def labels_dense(nb, dims, block_idx, block_w, pool_v, pool_w):
    """Ternary labels int8 [x, y, z]: 1 occupied (w > 0, v <= 0), 0 unknown (w = 0), -1 empty."""
    out = np.zeros((dims[0], dims[1], dims[2]), dtype=np.int8)
    nbx, nby, nbz = nb[0], nb[1], nb[2]
    for bx in prange(nbx):
        for by in range(nby):
            for bz in range(nbz):
                i = block_idx[bx, by, bz]
                bw = block_w[bx, by, bz]
                for lx in range(B):
                    gx = bx * B + lx
                    if gx >= dims[0]:
                        break
                    for ly in range(B):
                        gy = by * B + ly
                        if gy >= dims[1]:
                            break
                        for lz in range(B):
                            gz = bz * B + lz
                            if gz >= dims[2]:
                                break
                            if i < 0:
                                out[gx, gy, gz] = -1 if bw > 0 else 0
                            else:
                                k = lx * 64 + ly * 8 + lz
                                if pool_w[i, k] == 0:
                                    out[gx, gy, gz] = 0
                                elif pool_v[i, k] <= 0:
                                    out[gx, gy, gz] = 1
                                else:
                                    out[gx, gy, gz] = -1
    return out


@njit(cache=True, parallel=True)
def dense_box(lo, hi, block_idx, block_w, pool_v, pool_w, pool_c, want_color):
    """Dense v (float32), w (uint8) and colour (uint8, or empty) over voxel box [lo, hi), copied block by block."""
    sx, sy, sz = hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]
    tv = np.zeros((sx, sy, sz), dtype=np.float32)
    tw = np.zeros((sx, sy, sz), dtype=np.uint8)
    has_c = want_color and pool_c.shape[0] > 0
    tc = np.zeros((sx if has_c else 0, sy, sz, 3), dtype=np.uint8)
    if sx <= 0 or sy <= 0 or sz <= 0:
        return tv, tw, tc
    bx0 = lo[0] // B
    bx1 = (hi[0] - 1) // B + 1
    by0 = lo[1] // B
    by1 = (hi[1] - 1) // B + 1
    bz0 = lo[2] // B
    bz1 = (hi[2] - 1) // B + 1
    for bx in prange(bx0, bx1):
        x0 = max(bx * B, lo[0])
        x1 = min(bx * B + B, hi[0])
        for by in range(by0, by1):
            y0 = max(by * B, lo[1])
            y1 = min(by * B + B, hi[1])
            for bz in range(bz0, bz1):
                z0 = max(bz * B, lo[2])
                z1 = min(bz * B + B, hi[2])
                i = block_idx[bx, by, bz]
                if i < 0:
                    bw = block_w[bx, by, bz]
                    if bw > 0:
                        for gx in range(x0, x1):
                            for gy in range(y0, y1):
                                for gz in range(z0, z1):
                                    tv[gx - lo[0], gy - lo[1], gz - lo[2]] = 1.0
                                    tw[gx - lo[0], gy - lo[1], gz - lo[2]] = bw
                    continue
                for gx in range(x0, x1):
                    for gy in range(y0, y1):
                        kb = (gx - bx * B) * 64 + (gy - by * B) * 8 - bz * B
                        for gz in range(z0, z1):
                            k = kb + gz
                            tv[gx - lo[0], gy - lo[1], gz - lo[2]] = pool_v[i, k] / V_SCALE
                            tw[gx - lo[0], gy - lo[1], gz - lo[2]] = pool_w[i, k]
                            if has_c:
                                tc[gx - lo[0], gy - lo[1], gz - lo[2], 0] = pool_c[i, k, 0]
                                tc[gx - lo[0], gy - lo[1], gz - lo[2], 1] = pool_c[i, k, 1]
                                tc[gx - lo[0], gy - lo[1], gz - lo[2], 2] = pool_c[i, k, 2]
    return tv, tw, tc


@njit(cache=True)
def sphere_blocks(nb, origin, vs, center, radius):
    """Classify blocks against a sphere: 0 outside, 1 partly inside, 2 entirely inside (flattened)."""
    nbx, nby, nbz = nb[0], nb[1], nb[2]
    out = np.zeros(nbx * nby * nbz, dtype=np.uint8)
    r2 = radius * radius
    ext = (B - 1) * vs
    for bx in range(nbx):
        lo0 = origin[0] + (bx * B + 0.5) * vs
        for by in range(nby):
            lo1 = origin[1] + (by * B + 0.5) * vs
            for bz in range(nbz):
                lo2 = origin[2] + (bz * B + 0.5) * vs
                # nearest point of the centre box to the sphere centre
                dx = max(lo0 - center[0], 0.0, center[0] - (lo0 + ext))
                dy = max(lo1 - center[1], 0.0, center[1] - (lo1 + ext))
                dz = max(lo2 - center[2], 0.0, center[2] - (lo2 + ext))
                if dx * dx + dy * dy + dz * dz >= r2:
                    continue
                fx = max(abs(lo0 - center[0]), abs(lo0 + ext - center[0]))
                fy = max(abs(lo1 - center[1]), abs(lo1 + ext - center[1]))
                fz = max(abs(lo2 - center[2]), abs(lo2 + ext - center[2]))
                out[(bx * nby + by) * nbz + bz] = 2 if fx * fx + fy * fy + fz * fz < r2 else 1
    return out


@njit(cache=True, parallel=True)
def clear_sphere_blocks(sph, nb, block_idx_flat, block_w_flat, pool_v, pool_w, origin, vs, center, radius):
    """Set v = 0, w = 0 for voxel centres strictly inside the sphere (partial blocks must have storage)."""
    nby, nbz = nb[1], nb[2]
    r2 = radius * radius
    for b in prange(sph.shape[0]):
        s = sph[b]
        if s == 0:
            continue
        i = block_idx_flat[b]
        if i < 0:
            if s == 2:
                block_w_flat[b] = 0
            continue
        bx = b // (nby * nbz)
        rem = b - bx * nby * nbz
        by = rem // nbz
        bz = rem - by * nbz
        for lx in range(B):
            dx = origin[0] + (bx * B + lx + 0.5) * vs - center[0]
            for ly in range(B):
                dy = origin[1] + (by * B + ly + 0.5) * vs - center[1]
                for lz in range(B):
                    dz = origin[2] + (bz * B + lz + 0.5) * vs - center[2]
                    if dx * dx + dy * dy + dz * dz < r2:
                        k = lx * 64 + ly * 8 + lz
                        pool_v[i, k] = 0
                        pool_w[i, k] = 0


@njit(cache=True, inline="always")
def _corner(block_idx, block_w, pool_v, pool_w, dims, gx, gy, gz):
    """Voxel (gx, gy, gz)'s v as stored (v * V_SCALE; a known-empty uniform block: V_SCALE) and whether it is
    known (inside the grid, weight > 0)."""
    if gx < 0 or gy < 0 or gz < 0 or gx >= dims[0] or gy >= dims[1] or gz >= dims[2]:
        return 0.0, False
    i = block_idx[gx >> 3, gy >> 3, gz >> 3]
    if i < 0:
        return V_SCALE, block_w[gx >> 3, gy >> 3, gz >> 3] != 0
    k = (gx & 7) * 64 + (gy & 7) * 8 + (gz & 7)
    return float(pool_v[i, k]), pool_w[i, k] != 0


@njit(cache=True)
def _trilinear_any(block_idx, block_w, pool_v, pool_w, dims, gxf, gyf, gzf):
    """_trilinear for any 8 corners (across blocks, uniform blocks, the grid's border): each corner looked up on
    its own; the same interpolation order as _trilinear's fast path, so both give the same bits."""
    x0 = int(math.floor(gxf))
    y0 = int(math.floor(gyf))
    z0 = int(math.floor(gzf))
    v000, k000 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0, y0, z0)
    v001, k001 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0, y0, z0 + 1)
    v010, k010 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0, y0 + 1, z0)
    v011, k011 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0, y0 + 1, z0 + 1)
    v100, k100 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0 + 1, y0, z0)
    v101, k101 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0 + 1, y0, z0 + 1)
    v110, k110 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0 + 1, y0 + 1, z0)
    v111, k111 = _corner(block_idx, block_w, pool_v, pool_w, dims, x0 + 1, y0 + 1, z0 + 1)
    if not (k000 and k001 and k010 and k011 and k100 and k101 and k110 and k111):
        return 0.0, False
    return _lerp8(v000, v001, v010, v011, v100, v101, v110, v111, gxf - x0, gyf - y0, gzf - z0), True


@njit(cache=True, inline="always")
def _lerp8(v000, v001, v010, v011, v100, v101, v110, v111, rx, ry, rz):
    """Trilinear interpolation of 8 corner values (scaled by V_SCALE; corner xyz offsets as the index bits)."""
    c00 = v000 * (1.0 - rz) + v001 * rz
    c01 = v010 * (1.0 - rz) + v011 * rz
    c10 = v100 * (1.0 - rz) + v101 * rz
    c11 = v110 * (1.0 - rz) + v111 * rz
    c0 = c00 * (1.0 - ry) + c01 * ry
    c1 = c10 * (1.0 - ry) + c11 * ry
    return (c0 * (1.0 - rx) + c1 * rx) / V_SCALE


@njit(cache=True, inline="always")
def _trilinear(block_idx, block_w, pool_v, pool_w, dims, gxf, gyf, gzf):
    """Trilinear v at continuous voxel coordinates (voxel centres at integers); ok False if a corner is unknown.
    Fast path: when the 8 corners lie in one allocated block (2 points in 3 near a surface), read them from its
    pool row directly instead of looking the block up 8 times (halves a ray cast's time)."""
    x0 = int(math.floor(gxf))
    y0 = int(math.floor(gyf))
    z0 = int(math.floor(gzf))
    if ((x0 & 7) != 7 and (y0 & 7) != 7 and (z0 & 7) != 7 and x0 >= 0 and y0 >= 0 and z0 >= 0
            and x0 + 1 < dims[0] and y0 + 1 < dims[1] and z0 + 1 < dims[2]):
        i = block_idx[x0 >> 3, y0 >> 3, z0 >> 3]
        if i >= 0:
            k = (x0 & 7) * 64 + (y0 & 7) * 8 + (z0 & 7)
            if (pool_w[i, k] == 0 or pool_w[i, k + 1] == 0 or pool_w[i, k + 8] == 0 or pool_w[i, k + 9] == 0
                    or pool_w[i, k + 64] == 0 or pool_w[i, k + 65] == 0 or pool_w[i, k + 72] == 0
                    or pool_w[i, k + 73] == 0):
                return 0.0, False
            return _lerp8(float(pool_v[i, k]), float(pool_v[i, k + 1]), float(pool_v[i, k + 8]),
                          float(pool_v[i, k + 9]), float(pool_v[i, k + 64]), float(pool_v[i, k + 65]),
                          float(pool_v[i, k + 72]), float(pool_v[i, k + 73]), gxf - x0, gyf - y0, gzf - z0), True
    return _trilinear_any(block_idx, block_w, pool_v, pool_w, dims, gxf, gyf, gzf)


@njit(cache=True, error_model="numpy")
def _normal(block_idx, block_w, pool_v, pool_w, dims, cxf, cyf, czf, dx, dy, dz):
    """Unit TSDF gradient at continuous voxel coordinates, facing the ray (dx, dy, dz); ok False when unknown."""
    gxp, o1 = _trilinear(block_idx, block_w, pool_v, pool_w, dims, cxf + 1.0, cyf, czf)
    gxm, o2 = _trilinear(block_idx, block_w, pool_v, pool_w, dims, cxf - 1.0, cyf, czf)
    gyp, o3 = _trilinear(block_idx, block_w, pool_v, pool_w, dims, cxf, cyf + 1.0, czf)
    gym, o4 = _trilinear(block_idx, block_w, pool_v, pool_w, dims, cxf, cyf - 1.0, czf)
    gzp, o5 = _trilinear(block_idx, block_w, pool_v, pool_w, dims, cxf, cyf, czf + 1.0)
    gzm, o6 = _trilinear(block_idx, block_w, pool_v, pool_w, dims, cxf, cyf, czf - 1.0)
    if not ((o1 or o2) and (o3 or o4) and (o5 or o6)):
        return 0.0, 0.0, 0.0, False
    # central differences; where one side is unknown (thin band, coarse voxels) a one-sided difference against
    # the hit point (v = 0 there)
    nx = ((gxp if o1 else 0.0) - (gxm if o2 else 0.0)) * (0.5 if (o1 and o2) else 1.0)
    ny = ((gyp if o3 else 0.0) - (gym if o4 else 0.0)) * (0.5 if (o3 and o4) else 1.0)
    nz = ((gzp if o5 else 0.0) - (gzm if o6 else 0.0)) * (0.5 if (o5 and o6) else 1.0)
    nn = math.sqrt(nx * nx + ny * ny + nz * nz)
    if nn < 1e-9:
        return 0.0, 0.0, 0.0, False
    if nx * dx + ny * dy + nz * dz > 0.0:
        nn = -nn
    return nx / nn, ny / nn, nz / nn, True


@njit(cache=True, parallel=True)
def raycast_kernel(dims, block_idx, block_w, pool_v, pool_w, origin, vs, trunc,
                   T_wc, Kinv, width, height, tmin_ray, tmax_ray, stop_unknown):
    """Per pixel: first + to - zero crossing (or first occupied voxel) along the ray.

    Returns depth (z in the camera frame, 0 = no hit), world vertices and world normals (NaN = no hit),
    and state per pixel: 1 hit occupied, 0 met unknown space, -1 left through known-empty space only.
    With stop_unknown the ray also stops at the first unknown voxel (NBV: the first non-empty voxel), whose
    position is returned as the vertex (depth and normal stay 0 / NaN).

    One function on purpose (hot path, ~150 lines): grid clipping, the march that jumps over uniform blocks,
    the zero-crossing refinement and the normal all share a dozen per-ray variables inside one prange body;
    split into numba functions they would pass them all back and forth for every pixel.
    """
    depth = np.zeros((height, width), dtype=np.float32)
    verts = np.full((height, width, 3), np.nan, dtype=np.float32)
    norms = np.full((height, width, 3), np.nan, dtype=np.float32)
    state = np.zeros((height, width), dtype=np.int8)
    ox = T_wc[0, 3]
    oy = T_wc[1, 3]
    oz = T_wc[2, 3]
    inv_vs = 1.0 / vs
    bmin0 = origin[0]
    bmin1 = origin[1]
    bmin2 = origin[2]
    bmax0 = origin[0] + dims[0] * vs
    bmax1 = origin[1] + dims[1] * vs
    bmax2 = origin[2] + dims[2] * vs
    for pv in prange(height):
        for pu in range(width):
            # ray direction in camera coordinates (z = 1), then world
            xc = Kinv[0, 0] * pu + Kinv[0, 1] * pv + Kinv[0, 2]
            yc = Kinv[1, 0] * pu + Kinv[1, 1] * pv + Kinv[1, 2]
            zc = 1.0
            nrm = math.sqrt(xc * xc + yc * yc + zc * zc)
            dx = (T_wc[0, 0] * xc + T_wc[0, 1] * yc + T_wc[0, 2] * zc) / nrm
            dy = (T_wc[1, 0] * xc + T_wc[1, 1] * yc + T_wc[1, 2] * zc) / nrm
            dz = (T_wc[2, 0] * xc + T_wc[2, 1] * yc + T_wc[2, 2] * zc) / nrm
            # clip to the grid box (slab method)
            t0 = tmin_ray * nrm
            t1 = tmax_ray * nrm
            for ax in range(3):
                o = ox if ax == 0 else (oy if ax == 1 else oz)
                d = dx if ax == 0 else (dy if ax == 1 else dz)
                lo = bmin0 if ax == 0 else (bmin1 if ax == 1 else bmin2)
                hi = bmax0 if ax == 0 else (bmax1 if ax == 1 else bmax2)
                if abs(d) < 1e-12:
                    if o < lo or o > hi:
                        t1 = -1.0
                else:
                    ta = (lo - o) / d
                    tb = (hi - o) / d
                    if ta > tb:
                        ta, tb = tb, ta
                    t0 = max(t0, ta)
                    t1 = min(t1, tb)
            if t1 <= t0:
                state[pv, pu] = -1  # the ray misses the grid: nothing unknown on it
                continue
            t = t0
            prev_v = 0.0
            prev_t = t0
            prev_known = False
            any_unknown = False
            hit = False
            while t < t1:
                px = ox + dx * t
                py = oy + dy * t
                pz = oz + dz * t
                gx = int((px - bmin0) * inv_vs)
                gy = int((py - bmin1) * inv_vs)
                gz = int((pz - bmin2) * inv_vs)
                if gx < 0 or gy < 0 or gz < 0 or gx >= dims[0] or gy >= dims[1] or gz >= dims[2]:
                    t += 0.5 * vs
                    continue
                i = block_idx[gx >> 3, gy >> 3, gz >> 3]
                if i < 0:
                    bw = block_w[gx >> 3, gy >> 3, gz >> 3]
                    if bw == 0:
                        any_unknown = True
                        prev_known = False
                        if stop_unknown:
                            verts[pv, pu, 0] = px
                            verts[pv, pu, 1] = py
                            verts[pv, pu, 2] = pz
                            break
                    else:
                        prev_known = True
                        prev_v = 1.0
                    prev_t = t
                    # jump to the exit of this uniform block
                    tex = t1
                    for ax in range(3):
                        d = dx if ax == 0 else (dy if ax == 1 else dz)
                        g = gx if ax == 0 else (gy if ax == 1 else gz)
                        o = ox if ax == 0 else (oy if ax == 1 else oz)
                        lo = bmin0 if ax == 0 else (bmin1 if ax == 1 else bmin2)
                        if d > 1e-12:
                            tex = min(tex, (lo + ((g >> 3) + 1) * B * vs - o) / d)
                        elif d < -1e-12:
                            tex = min(tex, (lo + (g >> 3) * B * vs - o) / d)
                    t = max(tex + 1e-5, t + 0.25 * vs)
                    continue
                k = (gx & 7) * 64 + (gy & 7) * 8 + (gz & 7)
                w = pool_w[i, k]
                v = pool_v[i, k] / V_SCALE
                if w == 0:
                    any_unknown = True
                    prev_known = False
                    if stop_unknown:
                        verts[pv, pu, 0] = px
                        verts[pv, pu, 1] = py
                        verts[pv, pu, 2] = pz
                        break
                    prev_t = t
                    t += 0.5 * vs
                    continue
                if v <= 0.0:
                    th = t
                    if prev_known and prev_v > 0.0:
                        # refine with trilinear values where available
                        a, oka = _trilinear(block_idx, block_w, pool_v, pool_w, dims,
                                            (ox + dx * prev_t - bmin0) * inv_vs - 0.5,
                                            (oy + dy * prev_t - bmin1) * inv_vs - 0.5,
                                            (oz + dz * prev_t - bmin2) * inv_vs - 0.5)
                        c, okc = _trilinear(block_idx, block_w, pool_v, pool_w, dims,
                                            (px - bmin0) * inv_vs - 0.5, (py - bmin1) * inv_vs - 0.5,
                                            (pz - bmin2) * inv_vs - 0.5)
                        if oka and okc and a > 0.0 and c <= 0.0:
                            th = prev_t + (t - prev_t) * a / (a - c)
                        else:
                            th = prev_t + (t - prev_t) * prev_v / (prev_v - v)
                    hx = ox + dx * th
                    hy = oy + dy * th
                    hz = oz + dz * th
                    depth[pv, pu] = th / nrm
                    verts[pv, pu, 0] = hx
                    verts[pv, pu, 1] = hy
                    verts[pv, pu, 2] = hz
                    nx, ny, nz, ok_n = _normal(block_idx, block_w, pool_v, pool_w, dims, (hx - bmin0) * inv_vs - 0.5,
                                               (hy - bmin1) * inv_vs - 0.5, (hz - bmin2) * inv_vs - 0.5, dx, dy, dz)
                    if ok_n:
                        norms[pv, pu, 0] = nx
                        norms[pv, pu, 1] = ny
                        norms[pv, pu, 2] = nz
                    state[pv, pu] = 1
                    hit = True
                    break
                prev_known = True
                prev_v = v
                prev_t = t
                t += max(0.5 * vs, 0.8 * v * trunc)
            if not hit:
                state[pv, pu] = 0 if any_unknown else -1
    return depth, norms, verts, state


@njit(cache=True, parallel=True)
def occupied_blocks(block_idx, pool_v, pool_w):
    """Per block: True when it stores a known voxel with v <= 0 (only such blocks can hold a surface)."""
    nbx, nby, nbz = block_idx.shape
    out = np.zeros((nbx, nby, nbz), dtype=np.bool_)
    for bx in prange(nbx):
        for by in range(nby):
            for bz in range(nbz):
                i = block_idx[bx, by, bz]
                if i < 0:
                    continue
                for k in range(B3):
                    if pool_w[i, k] > 0 and pool_v[i, k] <= 0:
                        out[bx, by, bz] = True
                        break
    return out
