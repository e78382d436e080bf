"""Ray casting through the ternary map (numba): the paper's knowledge map and per-ray gain terms.

A ray starts at the sensor, is clipped to the volume box and to `max_range`, and walks the voxels it
crosses exactly (Amanatides & Woo 1987). It stops at the first voxel that is not EMPTY; the knowledge
map records whether that voxel is UNKNOWN (class 0) or OCCUPIED (class 1); a ray that leaves the
volume or reaches `max_range` through empty space only is EMPTY_EXIT (class 2). Empty space is crossed
in cubes known to be all EMPTY: at the block level (`block`^3 voxels, a chessboard distance in blocks to
the nearest block with a non-empty voxel) and, inside mixed blocks, at the voxel level (each EMPTY voxel
stores its chessboard distance to the nearest non-empty voxel, capped at FINE_CAP). Labels are stored
block by block (`RayVolume.bricks`) so a walk through a block touches a few cache lines.

Per ray the kernel also returns the terms the gain functions sum (see `gains.py`), all restricted to
voxels whose centre lies in the region S (centre, radius) and to hits at least `min_range` away:
  0 unknown   1 if the ray stops on an unknown voxel in S (the paper's eq. 2.10)
  1 distance  that hit weighted by 1 / t^2 (t in metres; depth noise grows with distance)
  2 rear      1 if, walking on through unknown space, the ray meets an occupied voxel right after an
              unknown voxel in S (the rear side of an already seen surface; Delmerico et al. 2018)
  3 entropy   sum over unknown voxels in S crossed before the first occupied voxel of
              P_visible * H(p_unknown), P_visible = (1 - p_unknown) ^ (unknown voxels before it)
              (occlusion-aware entropy, Isler et al. ICRA 2016; known voxels carry no entropy)
Terms 2 and 3 need the ray to continue through unknown space (`through=True`).

Rays do not walk the empty space before the scene alone: each 8 x 8 bundle of lattice rays marches its
cone once (`_cone_starts`) until the cone comes near a non-empty voxel, and its rays start there.

Camera rays of views that differ only by a roll about the optical axis (the paper's 8 rolls at each
sphere position) are cast once per position on the first view's pixel lattice; every view then looks
up its pixels' nearest lattice ray (`share_rolls`, exact for a single view or a roll that maps the
pixel grid onto itself). Only rays that can reach a voxel of S are cast when `restrict=True`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import numba
from numba import njit, prange
from scipy.ndimage import binary_dilation, distance_transform_cdt

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import TernaryGrid

CLS_UNKNOWN = 0
CLS_OCCUPIED = 1
CLS_EMPTY_EXIT = 2
N_TERMS = 4
_CHUNK = 256  # rays per scheduling chunk of the caster (see _cast_lattice)
_TILE = 16  # lattice tile side: rays are numbered tile by tile (see _mark_templates)
_LANES = 32  # accumulation lanes of the caster (see _cast_lattice)
FINE_CAP = 4  # cap of the voxel-level distances in mixed blocks (see _fill_bricks)
_CONE = 8  # side (lattice cells) of the ray bundles that march their free start together (see _cone_starts)
# Views sharing rolls are cast on one lattice, the bounding box of their pixel windows turned into the first view:
# for a window about as tall as wide it is at most twice one window. A wide and short window turned by 45 deg spans
# its width squared (a 100000 x 2 px sensor: 26525^2 = 7e8 cells for 8 windows of 53 k px, out of memory); when the
# lattice holds more than this many times the windows' pixels together, each view is cast on its own.
SHARED_LATTICE_SLACK = 2


@dataclass
class RayVolume:
    """A TernaryGrid prepared for ray casting: C-contiguous labels plus, per block of `block`^3 voxels
    (`block` a power of two), `block_dist`: 0 if the block holds a non-empty voxel, else the chessboard
    distance (in blocks) to the nearest such block, so the cube of (2 d - 1)^3 blocks around it is all
    EMPTY and a ray can cross it in one step. The caster reads labels block by block: `bricks` holds each
    block's `block`^3 labels contiguously (x, y, z order inside), at brick `brick_of[block]`; blocks of a
    single label share one brick (0 all EMPTY, 1 all UNKNOWN, 2 all OCCUPIED), so only mixed blocks cost
    memory and a ray's walk through a block stays in one or a few cache lines."""

    labels: np.ndarray
    origin: np.ndarray
    voxel_size: float
    block: int
    block_dist: np.ndarray
    bricks: np.ndarray
    brick_of: np.ndarray
    _code: np.ndarray | None = field(default=None, repr=False, compare=False)

    @classmethod
    def from_grid(cls, grid: TernaryGrid, block: int = 8, fine_cap: int = FINE_CAP) -> "RayVolume":
        block = int(block)
        if block < 1 or block & (block - 1) or block > 16:
            raise ConfigError(f"expected a power of two from 1 to 16, got {block}", parameter="block")
        labels = np.ascontiguousarray(grid.labels, dtype=np.int8)
        kind = _block_kind(labels, block)
        mixed = np.ascontiguousarray(np.argwhere(kind == 3))  # argwhere's order varies: one compiled kernel
        brick_of = np.where(kind == 3, 0, kind).astype(np.int32)
        brick_of[tuple(mixed.T)] = 3 + np.arange(len(mixed), dtype=np.int32)
        bricks = np.empty((3 + len(mixed)) * block ** 3, np.int8)
        _fill_bricks(labels, block, min(int(fine_cap), 127), mixed, brick_of, bricks)
        return cls(labels, np.asarray(grid.origin, dtype=np.float64), float(grid.voxel_size), block,
                   _chessboard(kind == 0), bricks, brick_of)

    def block_code(self) -> np.ndarray:
        """What the caster reads per block, one array so one memory access: -block_dist for free blocks,
        else the brick number (int16 when the bricks allow: half the cache footprint). Built at the first
        cast: change block_dist or brick_of only before it."""
        if self._code is None:
            dt = np.int16 if len(self.bricks) // self.block ** 3 < 32768 else np.int32
            self._code = np.ascontiguousarray(np.where(self.block_dist > 0, -self.block_dist.astype(np.int32),
                                                       self.brick_of).astype(dt))
        return self._code

    @property
    def shift(self) -> int:
        return int(self.block).bit_length() - 1

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.labels.shape)  # type: ignore[return-value]

    def optimistic_for(self, center, radius: float) -> "RayVolume":
        """The same volume with a distance field in which blocks holding only EMPTY voxels or UNKNOWN
        voxels far from the region (centre, radius) count as free: what optimistic rays may skip."""
        free = _block_free_outside(self.labels, self.block, self.origin, self.voxel_size,
                                   np.asarray(center, dtype=np.float64).reshape(3), float(radius))
        return RayVolume(self.labels, self.origin, self.voxel_size, self.block, _chessboard(free), self.bricks,
                         self.brick_of)

    def label_at(self, points: np.ndarray) -> np.ndarray:
        """Labels at world points (N, 3); points outside the volume read as EMPTY (-1), see `inside`."""
        idx = np.floor((np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.origin) / self.voxel_size)
        idx = idx.astype(np.int64)
        inside = np.all((idx >= 0) & (idx < np.array(self.shape)), axis=1)
        out = np.full(idx.shape[0], -1, dtype=np.int8)
        out[inside] = self.labels[idx[inside, 0], idx[inside, 1], idx[inside, 2]]
        return out

    def inside(self, points: np.ndarray) -> np.ndarray:
        idx = np.floor((np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.origin) / self.voxel_size)
        return np.all((idx >= 0) & (idx < np.array(self.shape)), axis=1)


def _chessboard(free: np.ndarray) -> np.ndarray:
    """Per block: 0 where not free, else the chessboard distance (in blocks, capped at 255) to the
    nearest block that is not free."""
    if free.all():
        return np.full(free.shape, 255, np.uint8)
    return np.ascontiguousarray(np.minimum(distance_transform_cdt(free, metric="chessboard"), 255).astype(np.uint8))


@njit(cache=True, inline="always")
def _gap(q, lo_a, hi_a):
    """Squared distance from q to the interval [lo_a, hi_a]."""
    e = lo_a - q if q < lo_a else (q - hi_a if q > hi_a else 0.0)
    return e * e


@njit(cache=True, parallel=True)
def _block_free_outside(labels, B, lo, vs, cen, radius):
    """1 for blocks whose voxels are all EMPTY, or EMPTY/UNKNOWN with the block box farther than
    radius + a voxel diagonal from `cen`."""
    nx, ny, nz = labels.shape
    bx, by, bz = (nx + B - 1) // B, (ny + B - 1) // B, (nz + B - 1) // B
    out = np.zeros((bx, by, bz), dtype=np.uint8)
    r = radius + vs * 1.7320508
    for a in prange(bx):
        for b in range(by):
            for c in range(bz):
                # distance from the centre to the block's box
                d2 = (_gap(cen[0], lo[0] + a * B * vs, lo[0] + min(a * B + B, nx) * vs)
                      + _gap(cen[1], lo[1] + b * B * vs, lo[1] + min(b * B + B, ny) * vs)
                      + _gap(cen[2], lo[2] + c * B * vs, lo[2] + min(c * B + B, nz) * vs))
                far = d2 > r * r
                ok = 1
                for i in range(a * B, min(a * B + B, nx)):
                    for j in range(b * B, min(b * B + B, ny)):
                        for k in range(c * B, min(c * B + B, nz)):
                            v = labels[i, j, k]
                            if v == 1 or (v == 0 and not far):
                                ok = 0
                                break
                        if ok == 0:
                            break
                    if ok == 0:
                        break
                out[a, b, c] = ok
    return out


@njit(cache=True, parallel=True)
def _block_kind(labels, B):
    """Per block: 0 all EMPTY, 1 all UNKNOWN, 2 all OCCUPIED, 3 mixed."""
    nx, ny, nz = labels.shape
    bx, by, bz = (nx + B - 1) // B, (ny + B - 1) // B, (nz + B - 1) // B
    out = np.zeros((bx, by, bz), dtype=np.uint8)
    for a in prange(bx):
        for b in range(by):
            for c in range(bz):
                first = labels[a * B, b * B, c * B]
                same = True
                for i in range(a * B, min(a * B + B, nx)):
                    for j in range(b * B, min(b * B + B, ny)):
                        for k in range(c * B, min(c * B + B, nz)):
                            if labels[i, j, k] != first:
                                same = False
                                break
                        if not same:
                            break
                    if not same:
                        break
                out[a, b, c] = (first + 1) if same else 3
    return out


@njit(cache=True, parallel=True)
def _fill_bricks(labels, B, C, mixed, brick_of, bricks):
    """The three shared single-label bricks, then each mixed block's brick: UNKNOWN 0 and OCCUPIED 1 as in
    the grid, an EMPTY voxel as -d with d its chessboard distance (in voxels, capped at C) to the nearest
    non-empty voxel, so the caster can leave the cube of (2 d - 1)^3 EMPTY voxels around it in one step.
    Voxels past the volume count as EMPTY. The distance is separable (one axis after the other), computed
    on the block grown by C - 1 voxels."""
    nx, ny, nz = labels.shape
    B3 = B * B * B
    bricks[:B3] = -1
    bricks[B3:2 * B3] = 0
    bricks[2 * B3:3 * B3] = 1
    R = C - 1
    E = B + 2 * R
    for m in prange(mixed.shape[0]):
        a, b, c = mixed[m, 0], mixed[m, 1], mixed[m, 2]
        base = brick_of[a, b, c] * B3
        x0, y0, z0 = a * B - R, b * B - R, c * B - R
        # distance along z to the nearest non-empty voxel within R (else C), on the grown block's x and y
        dz = np.empty((E, E, B), np.int8)
        for i in range(E):
            x = x0 + i
            for j in range(E):
                y = y0 + j
                inside_xy = 0 <= x < nx and 0 <= y < ny
                for k in range(B):
                    d = C
                    if inside_xy:
                        for e in range(-R, R + 1):
                            z = z0 + R + k + e
                            if 0 <= z < nz and labels[x, y, z] != -1 and abs(e) < d:
                                d = abs(e)
                    dz[i, j, k] = d
        dyz = np.empty((E, B, B), np.int8)
        for i in range(E):
            for j in range(B):
                for k in range(B):
                    d = C
                    for e in range(-R, R + 1):
                        v = max(abs(e), dz[i, R + j + e, k])
                        if v < d:
                            d = v
                    dyz[i, j, k] = d
        for i in range(B):
            for j in range(B):
                for k in range(B):
                    d = C
                    for e in range(-R, R + 1):
                        v = max(abs(e), dyz[R + i + e, j, k])
                        if v < d:
                            d = v
                    x, y, z = a * B + i, b * B + j, c * B + k
                    lab = labels[x, y, z] if x < nx and y < ny and z < nz else -1
                    bricks[base + (i * B + j) * B + k] = lab if lab != -1 else -max(d, 1)


@njit(cache=True, inline="always")
def _next_boundary(i, step, a, b):
    """t at which the ray leaves voxel i along one axis (inf when it does not move along it); the ray
    crosses the plane of voxel boundary f at t = f * a + b."""
    if step > 0:
        return (i + 1) * a + b
    if step < 0:
        return i * a + b
    return np.inf


@njit(cache=True, inline="always")
def _clampi(v, a, b):
    return a if v < a else (b if v > b else v)


@njit(cache=True, error_model="numpy", inline="always")
def _trace(bricks, code, SH, n0, n1, n2, lx, ly, lz, vs, px, py, pz, dx, dy, dz, min_range, max_range,
           ccx, ccy, ccz, r2, through, optimistic, p_unknown, h_unknown, tstart=0.0):
    """Walk one ray (origin p, unit direction d, the volume's corner l, S's centre cc); returns (class, t of the
    first hit, the 4 gain terms, block skips, voxel steps). Scalars in and out, and inlined: an array view
    per ray costs atomic reference counts that the threads fight over. `tstart`: the walk begins there (the
    caller knows every voxel the ray crosses before it is EMPTY, see `_free_start`).

    One long function on purpose: it is the innermost loop of every NBV command, and the walk state
    (voxel, next boundaries, visibility) crossing between the empty-block skip and the voxel walk stays
    in registers only while both live in one compiled loop.
    """
    B = 1 << SH
    M = B - 1
    # clip to the volume box and the range
    t0 = tstart
    t1 = max_range
    eps = 1e-12
    if abs(dx) < eps:
        if px < lx or px > lx + n0 * vs:
            return CLS_EMPTY_EXIT, np.inf, 0.0, 0.0, 0.0, 0.0, 0, 0, 0
        ivx = np.inf
    else:
        ivx = 1.0 / dx
        ta, tb = (lx - px) * ivx, (lx + n0 * vs - px) * ivx
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    if abs(dy) < eps:
        if py < ly or py > ly + n1 * vs:
            return CLS_EMPTY_EXIT, np.inf, 0.0, 0.0, 0.0, 0.0, 0, 0, 0
        ivy = np.inf
    else:
        ivy = 1.0 / dy
        ta, tb = (ly - py) * ivy, (ly + n1 * vs - py) * ivy
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    if abs(dz) < eps:
        if pz < lz or pz > lz + n2 * vs:
            return CLS_EMPTY_EXIT, np.inf, 0.0, 0.0, 0.0, 0.0, 0, 0, 0
        ivz = np.inf
    else:
        ivz = 1.0 / dz
        ta, tb = (lz - pz) * ivz, (lz + n2 * vs - pz) * ivz
        t0 = max(t0, min(ta, tb))
        t1 = min(t1, max(ta, tb))
    if t0 >= t1:
        return CLS_EMPTY_EXIT, np.inf, 0.0, 0.0, 0.0, 0.0, 0, 0, 0
    sx = 1 if dx > eps else (-1 if dx < -eps else 0)
    sy = 1 if dy > eps else (-1 if dy < -eps else 0)
    sz = 1 if dz > eps else (-1 if dz < -eps else 0)
    tdx = abs(vs * ivx) if sx != 0 else np.inf
    tdy = abs(vs * ivy) if sy != 0 else np.inf
    tdz = abs(vs * ivz) if sz != 0 else np.inf
    # per axis: boundary plane f is crossed at t = f * a + b; at t the ray is in voxel floor(t * g + h)
    ivs = 1.0 / vs
    ax, bx_ = vs * ivx, (lx - px) * ivx
    ay, by_ = vs * ivy, (ly - py) * ivy
    az, bz_ = vs * ivz, (lz - pz) * ivz
    gx, hx = dx * ivs, (px - lx) * ivs
    gy, hy = dy * ivs, (py - ly) * ivs
    gz, hz = dz * ivs, (pz - lz) * ivs
    ix = _clampi(int(math.floor(t0 * gx + hx)), 0, n0 - 1)
    iy = _clampi(int(math.floor(t0 * gy + hy)), 0, n1 - 1)
    iz = _clampi(int(math.floor(t0 * gz + hz)), 0, n2 - 1)
    tmx = _next_boundary(ix, sx, ax, bx_)
    tmy = _next_boundary(iy, sy, ay, by_)
    tmz = _next_boundary(iz, sz, az, bz_)
    tcur = t0
    cls = CLS_EMPTY_EXIT
    thit = np.inf
    vis = 1.0
    prev_unknown_in_s = False
    v0 = v1 = v2 = v3 = 0.0
    nb = nf = nv = 0  # block skips, fine (voxel-level) skips and voxel steps taken (benchmark statistics)
    while True:
        bx, by, bz = ix >> SH, iy >> SH, iz >> SH
        cd = code[bx, by, bz]
        if cd < 0:
            D = -np.int64(cd)
            nb += 1
            # the cube of blocks [b - D + 1, b + D - 1] is empty: leave it in one step
            D1 = D - 1
            te, ix, iy, iz = _leave_box(max((bx - D1) * B, 0), min((bx + D1 + 1) * B, n0), max((by - D1) * B, 0),
                                        min((by + D1 + 1) * B, n1), max((bz - D1) * B, 0),
                                        min((bz + D1 + 1) * B, n2), sx, sy, sz, ax, bx_, ay, by_, az, bz_,
                                        gx, hx, gy, hy, gz, hz)
            if te >= t1 or ix < 0 or ix >= n0 or iy < 0 or iy >= n1 or iz < 0 or iz >= n2:
                break
            tmx = _next_boundary(ix, sx, ax, bx_)
            tmy = _next_boundary(iy, sy, ay, by_)
            tmz = _next_boundary(iz, sz, az, bz_)
            tcur = te
            prev_unknown_in_s = False
            continue
        # walk voxel by voxel through this non-empty block
        xb0, yb0, zb0 = bx * B, by * B, bz * B  # this block's voxel range [b0, b0 + B) per axis
        base = np.int64(cd) << (3 * SH)
        while True:
            lab = bricks[base + ((((ix & M) << SH) | (iy & M)) << SH) + (iz & M)]
            if lab < -1:
                # an EMPTY voxel with no non-empty voxel closer than -lab (chessboard): leave that cube
                nf += 1
                d1 = -lab - 1
                te, ix, iy, iz = _leave_box(max(ix - d1, 0), min(ix + d1 + 1, n0), max(iy - d1, 0),
                                            min(iy + d1 + 1, n1), max(iz - d1, 0), min(iz + d1 + 1, n2), sx, sy, sz,
                                            ax, bx_, ay, by_, az, bz_, gx, hx, gy, hy, gz, hz)
                if te >= t1 or ix < 0 or ix >= n0 or iy < 0 or iy >= n1 or iz < 0 or iz >= n2:
                    return cls, thit, v0, v1, v2, v3, nb, nf, nv
                tmx = _next_boundary(ix, sx, ax, bx_)
                tmy = _next_boundary(iy, sy, ay, by_)
                tmz = _next_boundary(iz, sz, az, bz_)
                tcur = te
                prev_unknown_in_s = False
                if (ix >> SH) != bx or (iy >> SH) != by or (iz >> SH) != bz:
                    break
                continue
            nv += 1
            in_s = False
            dist2 = 0.0
            if lab >= 0:
                if tcur >= min_range:
                    qx = lx + (ix + 0.5) * vs - ccx
                    qy = ly + (iy + 0.5) * vs - ccy
                    qz = lz + (iz + 0.5) * vs - ccz
                    dist2 = qx * qx + qy * qy + qz * qz
                    in_s = dist2 <= r2
                if optimistic and lab == 0 and not in_s:
                    lab = -1  # unknown outside S: assumed free, the ray goes on
            if lab >= 0:
                if cls == CLS_EMPTY_EXIT:
                    thit = tcur
                    if lab == 0:
                        cls = CLS_UNKNOWN
                        if in_s:
                            v0 = 1.0
                            v1 = 1.0 / (tcur * tcur)
                    else:
                        cls = CLS_OCCUPIED
                    if not through:
                        return cls, thit, v0, v1, v2, v3, nb, nf, nv
                if lab == 0:
                    if in_s:
                        v3 += vis * h_unknown
                    vis *= 1.0 - p_unknown
                    prev_unknown_in_s = in_s
                    if vis < 1e-7:
                        return cls, thit, v0, v1, v2, v3, nb, nf, nv
                else:
                    if prev_unknown_in_s:
                        v2 = 1.0
                    return cls, thit, v0, v1, v2, v3, nb, nf, nv
            else:
                prev_unknown_in_s = False
            # one step; only the axis that moved can leave the volume or this block
            if tmx <= tmy and tmx <= tmz:
                tcur = tmx
                ix += sx
                tmx += tdx
                if ix < 0 or ix >= n0:
                    return cls, thit, v0, v1, v2, v3, nb, nf, nv
                left = ix < xb0 or ix >= xb0 + B
            elif tmy <= tmz:
                tcur = tmy
                iy += sy
                tmy += tdy
                if iy < 0 or iy >= n1:
                    return cls, thit, v0, v1, v2, v3, nb, nf, nv
                left = iy < yb0 or iy >= yb0 + B
            else:
                tcur = tmz
                iz += sz
                tmz += tdz
                if iz < 0 or iz >= n2:
                    return cls, thit, v0, v1, v2, v3, nb, nf, nv
                left = iz < zb0 or iz >= zb0 + B
            if tcur >= t1:
                return cls, thit, v0, v1, v2, v3, nb, nf, nv
            if left:
                break
    return cls, thit, v0, v1, v2, v3, nb, nf, nv


@njit(cache=True, inline="always")
def _leave_box(x0, x1, y0, y1, z0, z1, sx, sy, sz, ax, bx, ay, by, az, bz, gx, hx, gy, hy, gz, hz):
    """The ray is inside the all-EMPTY box of voxels [x0, x1) x [y0, y1) x [z0, z1): the t where it leaves
    the box and the voxel just past that face (the other two indices from the position, kept in the box).
    It crosses boundary plane f of an axis at t = f * a + b and is in voxel floor(t * g + h) at t."""
    ex = np.inf
    if sx > 0:
        ex = x1 * ax + bx
    elif sx < 0:
        ex = x0 * ax + bx
    ey = np.inf
    if sy > 0:
        ey = y1 * ay + by
    elif sy < 0:
        ey = y0 * ay + by
    ez = np.inf
    if sz > 0:
        ez = z1 * az + bz
    elif sz < 0:
        ez = z0 * az + bz
    te = min(ex, min(ey, ez))
    if ex <= ey and ex <= ez:
        ix = x1 if sx > 0 else x0 - 1
        iy = _clampi(int(math.floor(te * gy + hy)), y0, y1 - 1)
        iz = _clampi(int(math.floor(te * gz + hz)), z0, z1 - 1)
    elif ey <= ez:
        iy = y1 if sy > 0 else y0 - 1
        ix = _clampi(int(math.floor(te * gx + hx)), x0, x1 - 1)
        iz = _clampi(int(math.floor(te * gz + hz)), z0, z1 - 1)
    else:
        iz = z1 if sz > 0 else z0 - 1
        ix = _clampi(int(math.floor(te * gx + hx)), x0, x1 - 1)
        iy = _clampi(int(math.floor(te * gy + hy)), y0, y1 - 1)
    return te, ix, iy, iz


@njit(cache=True, parallel=True, error_model="numpy")
def _cast_kernel(shape, bricks, code, SH, lo, vs, origins, dirs, min_range, max_range, cen, radius, through,
                 optimistic, p_unknown, out_cls, out_t, out_vals):
    n = dirs.shape[0]
    r2 = radius * radius
    h = 0.0
    if 0.0 < p_unknown < 1.0:
        h = -(p_unknown * math.log2(p_unknown) + (1 - p_unknown) * math.log2(1 - p_unknown))
    for r in prange(n):
        c_, t_, v0, v1, v2, v3, _nb, _nf, _nv = _trace(bricks, code, SH, shape[0], shape[1], shape[2],
                                                  lo[0], lo[1], lo[2], vs, origins[r, 0],
                                                  origins[r, 1], origins[r, 2], dirs[r, 0], dirs[r, 1], dirs[r, 2],
                                                  min_range, max_range, cen[0], cen[1], cen[2], r2, through,
                                                  optimistic, p_unknown, h)
        out_cls[r] = c_
        out_t[r] = t_
        out_vals[r, 0], out_vals[r, 1], out_vals[r, 2], out_vals[r, 3] = v0, v1, v2, v3


@dataclass
class RayResults:
    """Per-ray knowledge map: cls (N,) int8 0 unknown / 1 occupied / 2 empty-exit, t (N,) distance of
    the first non-empty voxel (inf for empty-exit), terms (N, 4) gain terms (see module docstring)."""

    cls: np.ndarray
    t: np.ndarray
    terms: np.ndarray


def cast_rays(vol: RayVolume, origins: np.ndarray, dirs: np.ndarray, *, min_range: float = 0.0,
              max_range: float = np.inf, center=(0.0, 0.0, 0.0), radius: float = 0.0, through: bool = False,
              optimistic: bool = False, p_unknown: float = 0.5) -> RayResults:
    """Cast rays (origins (N, 3) or (3,), unit dirs (N, 3), world frame) through `vol`. `optimistic`:
    unknown voxels outside S are taken as free (rays stop only on occupied voxels or unknown ones in S)."""
    dirs = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    # a writable copy: a read-only view (broadcast_to's) is another type to numba, another 35 s compilation
    origins = np.array(np.broadcast_to(np.asarray(origins, dtype=np.float64), dirs.shape), order="C")
    n = dirs.shape[0]
    cls = np.empty(n, np.int8)
    t = np.empty(n, np.float64)
    terms = np.empty((n, N_TERMS), np.float64)
    _cast_kernel(vol.shape, vol.bricks, vol.block_code(), vol.shift, vol.origin, vol.voxel_size, origins, dirs,
                 float(min_range), float(min(max_range, 1e30)), np.asarray(center, dtype=np.float64).reshape(3),
                 float(radius), bool(through), bool(optimistic), float(p_unknown), cls, t, terms)
    return RayResults(cls, t, terms)


def knowledge_map(vol: RayVolume, pose: np.ndarray, camera, *, center=(0.0, 0.0, 0.0), radius: float = 0.0,
                  through: bool = False) -> RayResults:
    """Cast every pixel of one view (camera-to-world `pose`); arrays reshape to (height, width)."""
    pose = np.asarray(pose, dtype=np.float64)
    cam = camera.widened()
    dirs = cam.pixel_rays() @ pose[:3, :3].T
    return cast_rays(vol, pose[:3, 3], dirs, min_range=cam.min_range, max_range=cam.max_range, center=center,
                     radius=radius, through=through)


# ---------------------------------------------------------------------------------------------
# Batched views: rays of views sharing a sensor position and optical axis are cast once.


@njit(cache=True)
def _cone_bbox(ax, az, sin_a, f, c, size):
    """Pixel interval [lo, hi] of one image axis reachable by a cone of half-angle asin(sin_a) whose
    unit axis has components ax (along this image axis) and az (optical axis)."""
    rho = math.sqrt(ax * ax + az * az)
    if rho <= sin_a:
        return 0, size - 1
    th = math.atan2(ax, az)
    beta = math.asin(sin_a / rho)
    lo_t = th - beta
    hi_t = th + beta
    lim = math.pi / 2 - 1e-9
    if hi_t <= -lim or lo_t >= lim:
        return 0, -1
    lo_p = 0 if lo_t <= -lim else int(math.floor(f * math.tan(lo_t) + c))
    hi_p = size - 1 if hi_t >= lim else int(math.ceil(f * math.tan(hi_t) + c))
    return max(lo_p, 0), min(hi_p, size - 1)


@njit(cache=True, parallel=True)
def _mark_templates(tlat, loff, tcb, tcheck, fx, fy, cx, cy, r2, lut, tcount):
    """Per template: lattice cells whose ray (in the base view) can reach S get consecutive local ray
    numbers in `lut`, the others -1; tcount = rays per template."""
    for t in prange(tlat.shape[0]):
        lu0, lv0, LW, LH = tlat[t, 0], tlat[t, 1], tlat[t, 2], tlat[t, 3]
        cb = tcb[t]
        cbn2 = cb[0] * cb[0] + cb[1] * cb[1] + cb[2] * cb[2]
        n = 0
        # ray numbers go tile by tile (_TILE^2 cells, row-major inside): a scheduling chunk of the caster is
        # then a compact bundle of rays that read the same bricks, not one long row of the lattice
        for tile in range(((LH + _TILE - 1) // _TILE) * ((LW + _TILE - 1) // _TILE)):
            tv = tile // ((LW + _TILE - 1) // _TILE) * _TILE
            tu = tile % ((LW + _TILE - 1) // _TILE) * _TILE
            for cv in range(tv, min(tv + _TILE, LH)):
                for cu in range(tu, min(tu + _TILE, LW)):
                    ok = True
                    if tcheck[t]:
                        x = (cu + lu0 - cx) / fx
                        y = (cv + lv0 - cy) / fy
                        proj = cb[0] * x + cb[1] * y + cb[2]
                        ok = proj > 0 and cbn2 - proj * proj / (x * x + y * y + 1.0) <= r2
                    lut[loff[t] + cv * LW + cu] = n if ok else -1
                    n += 1 if ok else 0
        tcount[t] = n


@njit(cache=True, parallel=True)
def _fill_templates(tlat, loff, lut, tcount, toff, tview, vtmpl, woff, Ms, win, fx, fy, cx, cy, tcell, W, cap,
                    npix):
    """Per template: the lattice cell of each local ray (`tcell`) and, per view k of the template, how
    many of its pixels (inside its window) have that ray as nearest lattice ray (W[woff + ray * K + k]),
    and npix[m]: view m's pixels that have a nearest ray (the sum of its column of W), or -1 when a weight would
    pass `cap` (W's dtype holds whole numbers up to it; the caller then builds again in float32). Parallel over
    views (a pole position holds 96 of them), each writing its own column of W."""
    for t in prange(tlat.shape[0]):
        LW, LH = tlat[t, 2], tlat[t, 3]
        for c in range(LW * LH):
            r = lut[loff[t] + c]
            if r >= 0:
                tcell[toff[t] + r] = c
    for m in prange(Ms.shape[0]):
        t = vtmpl[m]
        lu0, lv0, LW, LH = tlat[t, 0], tlat[t, 1], tlat[t, 2], tlat[t, 3]
        K = tview[t + 1] - tview[t]
        k = m - tview[t]
        M = Ms[m]
        du0, du1, du2 = M[0, 0] / fx, M[1, 0] / fx, M[2, 0] / fx  # change of the ray per pixel along u
        cnt = 0
        over = False
        for vv in range(win[m, 1], win[m, 3] + 1):
            y = (vv - cy) / fy
            x = (win[m, 0] - cx) / fx
            dx = M[0, 0] * x + M[0, 1] * y + M[0, 2]
            dy = M[1, 0] * x + M[1, 1] * y + M[1, 2]
            dz = M[2, 0] * x + M[2, 1] * y + M[2, 2]
            for uu in range(win[m, 0], win[m, 2] + 1):
                if dz > 1e-12:
                    iz = 1.0 / dz
                    # nearest lattice cell (a 45 deg roll maps a line of pixels onto cell edges: the
                    # rounding noise of the template's rotation picks the side)
                    lu = int(math.floor(fx * dx * iz + cx + 0.5)) - lu0
                    lv = int(math.floor(fy * dy * iz + cy + 0.5)) - lv0
                    if lu >= 0 and lv >= 0 and lu < LW and lv < LH:
                        r = lut[loff[t] + lv * LW + lu]
                        if r >= 0:
                            wi = woff[t] + r * K + k
                            if W[wi] >= cap:
                                over = True
                            else:
                                W[wi] += 1
                            cnt += 1
                dx += du0
                dy += du1
                dz += du2
        npix[m] = -1 if over else cnt


@njit(cache=True, parallel=True)
def _template_dirs(tlat, toff, tcount, tcell, fx, fy, cx, cy, d):
    """Each template ray's unit direction in the base view, from its lattice cell: the numpy expression it
    replaces (x, y, 1) / |(x, y, 1)| op for op, so the directions are the same bits, without its
    temporaries (a dozen arrays of every ray of the batch, freshly mapped and faulted in per batch)."""
    for t in prange(tlat.shape[0]):
        lu0, lv0, LW = tlat[t, 0], tlat[t, 1], tlat[t, 2]
        for e in range(toff[t], toff[t] + tcount[t]):
            c = np.int64(tcell[e])
            x = (np.float64(c % LW + lu0) - cx) / fx
            y = (np.float64(c // LW + lv0) - cy) / fy
            n = math.sqrt(x * x + y * y + 1.0)
            d[e, 0] = x / n
            d[e, 1] = y / n
            d[e, 2] = 1.0 / n


@njit(cache=True, parallel=True, error_model="numpy")
def _cast_lattice(shape, bricks, code, SH, lo, vs, ray_off, gtmpl, toff, tdir, tview, woff, W, gview, R0s,
                  t0s, tcone, coff, cstart, min_range, max_range, cen, radius, through, optimistic, p_unknown, chunk,
                  acc, steps):
    """Trace every ray of every group (its direction is its template's ray turned by the group's base
    pose, so no per-ray origin/direction arrays) and add its results, times its template's pixel weights,
    to the sums of the group's views (columns gview[g] ... of acc, in the template's view order); a ray
    starts where its bundle's cone leaves free space: cstart[coff[g] + tcone[e]] (`_cone_starts`). Ray costs
    differ by orders of magnitude (a free-space skip vs a walk through clutter) and numba splits a prange
    into one contiguous slice per thread, so the rays are cut into small chunks dealt round-robin to the
    lanes (acc's first axis, a fixed number so sums do not depend on the thread count): every thread gets
    a share of every region, and each lane sums into its own rows (no ray arrays, no races).
    acc rows: rays ending on 0 unknown (no gain) / 1 occupied / 2 empty exit / 3 unknown in S (left at 0:
    the caller takes it as the views' pixels minus rows 0-2), then the sums of gain terms 1-3 (term 0 is
    row 3)."""
    lanes = acc.shape[0]
    n = ray_off[-1]
    nchunk = (n + chunk - 1) // chunk
    r2 = radius * radius
    h = 0.0
    if 0.0 < p_unknown < 1.0:
        h = -(p_unknown * math.log2(p_unknown) + (1 - p_unknown) * math.log2(1 - p_unknown))
    ng = ray_off.shape[0] - 1
    lx, ly, lz, ccx, ccy, ccz = lo[0], lo[1], lo[2], cen[0], cen[1], cen[2]
    n0, n1, n2 = shape
    for lane in prange(lanes):
        nbs = nfs = nvs = 0
        for k in range(lane, nchunk, lanes):
            q0 = k * chunk
            q1 = min(q0 + chunk, n)
            g = np.searchsorted(ray_off, q0, side="right") - 1
            for q in range(q0, q1):
                while q >= ray_off[g + 1]:
                    g += 1
                t = gtmpl[g]
                r = q - ray_off[g]
                e = toff[t] + r
                x, y, z = tdir[e, 0], tdir[e, 1], tdir[e, 2]
                dx = R0s[g, 0, 0] * x + R0s[g, 0, 1] * y + R0s[g, 0, 2] * z
                dy = R0s[g, 1, 0] * x + R0s[g, 1, 1] * y + R0s[g, 1, 2] * z
                dz = R0s[g, 2, 0] * x + R0s[g, 2, 1] * y + R0s[g, 2, 2] * z
                c_, _t, v0, v1, v2, v3, nb, nf, nv = _trace(bricks, code, SH, n0, n1, n2, lx, ly, lz, vs,
                                                            t0s[g, 0], t0s[g, 1], t0s[g, 2], dx, dy, dz, min_range,
                                                            max_range, ccx, ccy, ccz, r2, through, optimistic,
                                                            p_unknown, h, cstart[coff[g] + tcone[e]])
                col = 3 if v0 != 0.0 else c_
                K = tview[t + 1] - tview[t]
                w0 = woff[t] + r * K
                m0 = gview[g]
                if col != 3:  # rays ending on unknown in S are the rest, counted after the cast
                    for kk in range(K):
                        acc[lane, col, m0 + kk] += W[w0 + kk]
                if v1 != 0.0:
                    for kk in range(K):
                        acc[lane, 4, m0 + kk] += W[w0 + kk] * v1
                if v2 != 0.0:
                    for kk in range(K):
                        acc[lane, 5, m0 + kk] += W[w0 + kk] * v2
                if v3 != 0.0:
                    for kk in range(K):
                        acc[lane, 6, m0 + kk] += W[w0 + kk] * v3
                nbs += nb
                nfs += nf
                nvs += nv
        steps[lane, 0] = nbs
        steps[lane, 1] = nvs
        steps[lane, 2] = nfs


def _free_start(vol: RayVolume, sensors: np.ndarray, center, r_ext: float, check: np.ndarray) -> np.ndarray:
    """Per group: a distance along its rays before which every voxel they cross is EMPTY, so the walk can
    start there instead of crossing the free space around the sensor in block skips. The group's cast rays
    lie in the cone from its sensor towards S (half-angle asin(r_ext / distance); any direction when
    `check` is false); the first non-empty voxel a ray meets lies in a block that is not free and touches
    a free block (or the volume's faces), so the nearest box of such a block whose bounding sphere meets
    the cone bounds it from below (minus a thousandth of a voxel for rounding)."""
    free = vol.block_dist > 0
    edge = ~free & binary_dilation(free, np.ones((3, 3, 3), bool), border_value=1)
    blocks = np.argwhere(edge).astype(np.int64)
    out = np.zeros(len(sensors))
    if len(blocks):
        _free_start_kernel(blocks, vol.block * vol.voxel_size, vol.origin, np.asarray(sensors, np.float64),
                           np.asarray(center, np.float64).reshape(3), float(r_ext), check, out)
    # a sensor inside a block that is not free starts at 0 (its own block need not touch a free one)
    bi = np.floor((np.asarray(sensors, np.float64).reshape(-1, 3) - vol.origin) / (vol.block * vol.voxel_size))
    bi = bi.astype(np.int64)
    inside = np.all((bi >= 0) & (bi < np.array(free.shape)), axis=1)
    at = np.zeros(len(out), bool)
    at[inside] = ~free[bi[inside, 0], bi[inside, 1], bi[inside, 2]]
    out[at] = 0.0
    return np.maximum(out - 1e-3 * vol.voxel_size, 0.0)


@njit(cache=True, parallel=True)
def _free_start_kernel(blocks, bs, lo, P, cen, r_ext, check, out):
    """out[g]: the smallest distance from sensor P[g] to the box of a block (blocks (N, 3), side bs) whose
    bounding sphere meets the group's cone (apex P[g], axis to cen, sin of half-angle r_ext / distance)."""
    rb = bs * 0.8660254037844387 * (1.0 + 1e-9)
    for g in prange(P.shape[0]):
        ax, ay, az = cen[0] - P[g, 0], cen[1] - P[g, 1], cen[2] - P[g, 2]
        L = math.sqrt(ax * ax + ay * ay + az * az)
        cone = check[g] and L > r_ext
        sa = ca = 0.0
        if cone:
            ax, ay, az = ax / L, ay / L, az / L
            sa = min(r_ext / L * (1.0 + 1e-9), 1.0)
            ca = math.sqrt(1.0 - sa * sa)
        best = np.inf
        for m in range(blocks.shape[0]):
            x0, y0, z0 = lo[0] + blocks[m, 0] * bs, lo[1] + blocks[m, 1] * bs, lo[2] + blocks[m, 2] * bs
            d2 = (_gap(P[g, 0], x0, x0 + bs) + _gap(P[g, 1], y0, y0 + bs) + _gap(P[g, 2], z0, z0 + bs))
            if d2 >= best * best:
                continue
            if cone:
                # distance from the block's centre to the (one-sided) cone, against its bounding radius
                vx, vy, vz = x0 + 0.5 * bs - P[g, 0], y0 + 0.5 * bs - P[g, 1], z0 + 0.5 * bs - P[g, 2]
                along = vx * ax + vy * ay + vz * az
                perp = math.sqrt(max(vx * vx + vy * vy + vz * vz - along * along, 0.0))
                if perp * sa + along * ca < 0.0:
                    dc = math.sqrt(vx * vx + vy * vy + vz * vz)
                else:
                    dc = perp * ca - along * sa
                if dc > rb:
                    continue
            best = math.sqrt(d2)
        out[g] = best


@njit(cache=True)
def _bundle_cones(tdir, tcell, LW, side, ncu, cone, axis, chord):
    """One template's ray bundles: each ray's bundle (`cone`, a square of side x side lattice cells), the
    bundle's axis (unit mean direction) and its largest chord |u - axis| over its unit directions u, so a
    ray point at distance s from the sensor lies within s * chord of the axis point at s. Empty bundles
    keep a zero axis."""
    axis[:] = 0.0
    chord[:] = 0.0
    for e in range(tdir.shape[0]):
        k = (tcell[e] // LW) // side * ncu + (tcell[e] % LW) // side
        cone[e] = k
        axis[k, 0] += tdir[e, 0]
        axis[k, 1] += tdir[e, 1]
        axis[k, 2] += tdir[e, 2]
    for k in range(axis.shape[0]):
        n = math.sqrt(axis[k, 0] ** 2 + axis[k, 1] ** 2 + axis[k, 2] ** 2)
        if n > 0.0:
            axis[k, 0] /= n
            axis[k, 1] /= n
            axis[k, 2] /= n
    for e in range(tdir.shape[0]):
        k = cone[e]
        c = math.sqrt((tdir[e, 0] - axis[k, 0]) ** 2 + (tdir[e, 1] - axis[k, 1]) ** 2 + (tdir[e, 2] - axis[k, 2]) ** 2)
        chord[k] = max(chord[k], c)


@njit(cache=True, parallel=True)
def _cone_starts(bricks, code, SH, shape, lo, vs, gtmpl, R0s, t0s, tfree, tmax, ctoff, caxis, cchord, coff, out):
    """Per group and ray bundle: a distance before which every voxel any of the bundle's rays crosses is
    EMPTY, so each ray's walk starts there. From the group's free start (which must hold for the widest
    cone towards S) the bundle's axis point p(s) marches on: the rays' points at distances in
    [s, s + step] lie within (s + step) * chord + step of p(s), so the march may take a step whose ball
    around p is free (`_free_radius`), less a thousandth of a voxel; where that is under half a voxel, a
    half-block step when its box meets free blocks only (`_box_free`: a few block reads; the march takes a
    third longer with `_box_empty` alone), else a half-voxel step whose box of voxels is all EMPTY
    (`_box_empty`). It stops at the first box that is not: the cone then touches a non-empty voxel, and each ray walks the rest alone. No ray goes past
    tmax (the range, or the farthest corner of the volume)."""
    bs = vs * (1 << SH)
    n = coff[-1]
    for lane in prange(_LANES):  # bundles dealt round-robin: neighbours cost alike, groups do not
        for q in range(lane, n, _LANES):
            g = np.searchsorted(coff, q, side="right") - 1
            c = ctoff[gtmpl[g]] + q - coff[g]
            x, y, z = caxis[c, 0], caxis[c, 1], caxis[c, 2]
            s = tfree[g]
            if x != 0.0 or y != 0.0 or z != 0.0:
                R = R0s[g]
                ax = R[0, 0] * x + R[0, 1] * y + R[0, 2] * z
                ay = R[1, 0] * x + R[1, 1] * y + R[1, 2] * z
                az = R[2, 0] * x + R[2, 1] * y + R[2, 2] * z
                ch = cchord[c] * (1.0 + 1e-9) + 1e-12
                for _ in range(1024):
                    if s >= tmax[g]:
                        s = tmax[g]
                        break
                    px, py, pz = t0s[g, 0] + s * ax, t0s[g, 1] + s * ay, t0s[g, 2] + s * az
                    step = (_free_radius(bricks, code, SH, shape, lo, vs, px, py, pz) - s * ch) / (1.0 + ch)
                    step -= 1e-3 * vs
                    if step < 0.5 * vs:
                        # half a block if every block its box meets is free, else half a voxel if every
                        # voxel its box meets is EMPTY
                        step = 0.5 * bs
                        if not _box_free(code, SH, lo, vs, px, py, pz, (s + step) * ch + step + 1e-3 * vs):
                            step = 0.5 * vs
                            if not _box_empty(bricks, code, SH, shape, lo, vs, px, py, pz,
                                              (s + step) * ch + step + 1e-3 * vs):
                                break
                    s += step
            out[q] = s


@njit(cache=True, inline="always")
def _free_radius(bricks, code, SH, shape, lo, vs, px, py, pz):
    """A radius around p in which every voxel is EMPTY: outside the volume the distance to its box; in a
    free block the distance to the faces of its all-EMPTY cube of blocks; on an EMPTY voxel of a mixed
    block the distance to the faces of its cube of voxels (the brick's capped chessboard distance); 0
    elsewhere."""
    B = 1 << SH
    fx, fy, fz = (px - lo[0]) / vs, (py - lo[1]) / vs, (pz - lo[2]) / vs
    n0, n1, n2 = shape[0], shape[1], shape[2]
    if fx < 0 or fy < 0 or fz < 0 or fx >= n0 or fy >= n1 or fz >= n2:
        return math.sqrt(_gap(fx, 0.0, n0) + _gap(fy, 0.0, n1) + _gap(fz, 0.0, n2)) * vs
    ix, iy, iz = min(int(fx), n0 - 1), min(int(fy), n1 - 1), min(int(fz), n2 - 1)
    cd = code[ix >> SH, iy >> SH, iz >> SH]
    if cd < 0:
        # cube of blocks [b - D + 1, b + D - 1], in voxels
        D = -np.int64(cd)
        x0, y0, z0 = ((ix >> SH) - D + 1) * B, ((iy >> SH) - D + 1) * B, ((iz >> SH) - D + 1) * B
        w = (2 * D - 1) * B
    else:
        M = B - 1
        lab = bricks[(np.int64(cd) << (3 * SH)) + ((((ix & M) << SH) | (iy & M)) << SH) + (iz & M)]
        if lab >= 0:
            return 0.0
        d = -np.int64(lab)
        x0, y0, z0 = ix - d + 1, iy - d + 1, iz - d + 1
        w = 2 * d - 1
    r = min(min(fx - x0, x0 + w - fx), min(fy - y0, y0 + w - fy))
    return min(r, min(fz - z0, z0 + w - fz)) * vs


@njit(cache=True, inline="always")
def _box_free(code, SH, lo, vs, px, py, pz, r):
    """Whether every block meeting the cube of half-side r around p is free (outside the volume: free)."""
    bs = vs * (1 << SH)
    nbx, nby, nbz = code.shape
    x0 = max(int(math.floor((px - r - lo[0]) / bs)), 0)
    x1 = min(int(math.floor((px + r - lo[0]) / bs)), nbx - 1)
    y0 = max(int(math.floor((py - r - lo[1]) / bs)), 0)
    y1 = min(int(math.floor((py + r - lo[1]) / bs)), nby - 1)
    z0 = max(int(math.floor((pz - r - lo[2]) / bs)), 0)
    z1 = min(int(math.floor((pz + r - lo[2]) / bs)), nbz - 1)
    for i in range(x0, x1 + 1):
        for j in range(y0, y1 + 1):
            for k in range(z0, z1 + 1):
                if code[i, j, k] >= 0:
                    return False
    return True


@njit(cache=True, inline="always")
def _box_empty(bricks, code, SH, shape, lo, vs, px, py, pz, r):
    """Whether every voxel meeting the cube of half-side r around p is EMPTY, block by block: free blocks
    at once, single-label ones at once, mixed ones voxel by voxel from their bricks."""
    B = 1 << SH
    M = B - 1
    i0 = max(int(math.floor((px - r - lo[0]) / vs)), 0)
    i1 = min(int(math.floor((px + r - lo[0]) / vs)), shape[0] - 1)
    j0 = max(int(math.floor((py - r - lo[1]) / vs)), 0)
    j1 = min(int(math.floor((py + r - lo[1]) / vs)), shape[1] - 1)
    k0 = max(int(math.floor((pz - r - lo[2]) / vs)), 0)
    k1 = min(int(math.floor((pz + r - lo[2]) / vs)), shape[2] - 1)
    if i0 > i1 or j0 > j1 or k0 > k1:
        return True
    for a in range(i0 >> SH, (i1 >> SH) + 1):
        for b in range(j0 >> SH, (j1 >> SH) + 1):
            for c in range(k0 >> SH, (k1 >> SH) + 1):
                cd = code[a, b, c]
                if cd < 0:
                    continue
                if cd == 1 or cd == 2:
                    return False
                base = np.int64(cd) << (3 * SH)
                for i in range(max(i0, a << SH), min(i1, (a << SH) + M) + 1):
                    for j in range(max(j0, b << SH), min(j1, (b << SH) + M) + 1):
                        row = base + ((((i & M) << SH) | (j & M)) << SH)
                        for k in range(max(k0, c << SH), min(k1, (c << SH) + M) + 1):
                            if bricks[row + (k & M)] >= 0:
                                return False
    return True


@dataclass
class ViewRays:
    """Per-view sums over the pixels considered: counts (V, 3) of rays ending on unknown / occupied /
    empty-exit, terms (V, 4) summed gain terms, rays (V,) pixels considered, rays_cast rays traced;
    block_steps / fine_steps / voxel_steps: empty-block skips, voxel-level skips inside mixed blocks and
    single-voxel steps the traced rays took in all; templates: lattice templates built (groups with the
    same geometry about their sensor share one)."""

    counts: np.ndarray
    terms: np.ndarray
    rays: np.ndarray
    rays_cast: int
    block_steps: int = 0
    voxel_steps: int = 0
    templates: int = 0
    fine_steps: int = 0


def group_views(poses: np.ndarray, tol: float = 1e-6) -> list[np.ndarray]:
    """Indices of views that share sensor position and optical axis (they differ only by roll)."""
    poses = np.asarray(poses, dtype=np.float64)
    key = np.round(np.concatenate([poses[:, :3, 3], poses[:, :3, 2]], axis=1) / tol).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    order = np.argsort(inv, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(inv[order])) + 1)


def _pixel_window(R, t, cam, center, r_ext, restrict) -> tuple[int, int, int, int]:
    """Pixel bbox (u0, v0, u1, v1) of one view that can see the sphere (center, r_ext)."""
    W, H = cam.width, cam.height
    if not restrict:
        return 0, 0, W - 1, H - 1
    c = R.T @ (center - t)
    dist = float(np.linalg.norm(c))
    if dist <= r_ext:
        return 0, 0, W - 1, H - 1
    a = c / dist
    s = r_ext / dist
    u0, u1 = _cone_bbox(a[0], a[2], s, cam.fx, cam.cx, W)
    v0, v1 = _cone_bbox(a[1], a[2], s, cam.fy, cam.cy, H)
    return u0, v0, u1, v1


@dataclass
class _Group:
    """Views sharing a sensor position and optical axis: output rows `views`, rolls `Ms` relative to the
    base view (R0, t0), pixel windows `win`, and the key of their template (geometry relative to t0)."""

    views: np.ndarray
    Ms: np.ndarray
    win: np.ndarray
    lat: tuple[int, int, int, int]
    cb: np.ndarray
    check: bool
    R0: np.ndarray
    t0: np.ndarray
    key: tuple


def _template_key(lat, cb, check, Ms, win) -> tuple:
    """Groups with equal keys share lattice marks and pixel weights (rounding only merges float noise)."""
    return (lat, check, (np.round(cb, 9) + 0.0).tobytes(), (np.round(Ms, 12) + 0.0).tobytes(), win.tobytes())


def _group(poses: np.ndarray, views: np.ndarray, win: np.ndarray, cam, center: np.ndarray, r_ext: float,
           restrict: bool) -> _Group:
    """The _Group of `views` (sharing a sensor position and optical axis; the first is the base view) with their
    pixel windows `win`: its lattice is the windows' corners mapped into the base view (an affine map for a roll)."""
    R0, t0 = poses[views[0], :3, :3], poses[views[0], :3, 3]
    Ms = np.ascontiguousarray(np.einsum("ji,njk->nik", R0, poses[views, :3, :3]))
    cu = np.stack([win[:, 0], win[:, 2], win[:, 0], win[:, 2]], axis=1).astype(np.float64)
    cv = np.stack([win[:, 1], win[:, 1], win[:, 3], win[:, 3]], axis=1).astype(np.float64)
    d = np.einsum("nij,nkj->nki", Ms, np.stack([(cu - cam.cx) / cam.fx, (cv - cam.cy) / cam.fy,
                                                  np.ones_like(cu)], axis=-1))
    pu = cam.fx * d[..., 0] / d[..., 2] + cam.cx
    pv = cam.fy * d[..., 1] / d[..., 2] + cam.cy
    lu0, lv0 = int(np.floor(pu.min())) - 1, int(np.floor(pv.min())) - 1
    lat = (lu0, lv0, int(np.ceil(pu.max())) + 2 - lu0, int(np.ceil(pv.max())) + 2 - lv0)
    cb = R0.T @ (center - t0)
    check = bool(restrict and np.linalg.norm(cb) > r_ext)
    return _Group(views, Ms, win, lat, cb, check, R0, t0, _template_key(lat, cb, check, Ms, win))


def cast_views(vol: RayVolume, poses: np.ndarray, camera, center, radius: float, *, through: bool = False,
               optimistic: bool = False, restrict: bool = True, share_rolls: bool = True, p_unknown: float = 0.5,
               march: bool = True, batch_cells: int = 12_000_000, progress_cb=None,
               timings: dict | None = None) -> ViewRays:
    """Cast the rays of every view (camera-to-world `poses` (V, 4, 4)) and sum them per view.

    `restrict`: only pixels whose ray passes within radius + half a voxel diagonal of `center` (the
    only ones that can add gain); the counts then cover those pixels. `share_rolls`: views that differ
    only by roll reuse the first view's rays (nearest lattice ray). `optimistic`: unknown voxels
    outside S do not stop rays (see `cast_rays`). `march`: rays start where their bundle of 8 x 8
    lattice rays first comes near a non-empty voxel (`_cone_starts`; the same sums, fewer steps) instead
    of at their group's free start. `progress_cb(n)` after each batch. `timings`: when a
    dict, seconds per phase (setup, mark, cast, accumulate) are added to it (for the benchmark).
    """
    tick = _Ticker(timings)
    cam = camera.widened()
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    V = poses.shape[0]
    center = np.asarray(center, dtype=np.float64).reshape(3)
    r_ext = float(radius) + vol.voxel_size * math.sqrt(3.0) / 2.0
    out = ViewRays(np.zeros((V, 3), np.int64), np.zeros((V, N_TERMS)), np.zeros(V, np.int64), 0)
    groups = group_views(poses) if share_rolls else [np.array([i]) for i in range(V)]
    batch: list[_Group] = []
    cache: dict = {}
    used = 0
    for g in groups:
        win = np.array([_pixel_window(poses[i, :3, :3], poses[i, :3, 3], cam, center, r_ext, restrict) for i in g],
                       dtype=np.int64).reshape(-1, 4)
        ok = (win[:, 2] >= win[:, 0]) & (win[:, 3] >= win[:, 1])
        if progress_cb and not ok.all():
            progress_cb(int((~ok).sum()))
        if not ok.any():
            continue
        entry = _group(poses, g[ok], np.ascontiguousarray(win[ok]), cam, center, r_ext, restrict)
        pixels = int(np.sum((win[ok, 2] - win[ok, 0] + 1) * (win[ok, 3] - win[ok, 1] + 1)))
        if len(entry.views) > 1 and entry.lat[2] * entry.lat[3] > SHARED_LATTICE_SLACK * pixels:
            # each view on its own lattice, as without sharing (see SHARED_LATTICE_SLACK)
            entries = [_group(poses, g[ok][k:k + 1], win[ok][k:k + 1], cam, center, r_ext, restrict)
                       for k in range(len(entry.views))]
        else:
            entries = [entry]
        batch += entries
        used += sum(e.lat[2] * e.lat[3] for e in entries)
        if used >= batch_cells:
            tick("setup")
            _cast_batch(vol, cam, center, radius, r_ext, (through, optimistic, march), p_unknown, batch, cache, out,
                        progress_cb, tick)
            batch, used = [], 0
    tick("setup")
    if batch:
        _cast_batch(vol, cam, center, radius, r_ext, (through, optimistic, march), p_unknown, batch, cache, out,
                    progress_cb, tick)
    return out


class _Ticker:
    """Adds the wall seconds since the last call to `timings[phase]` and the CPU seconds (all threads) to
    `timings[phase + "_cpu"]` (nothing when timings is None)."""

    def __init__(self, timings: dict | None):
        self.timings = timings
        self.t, self.c = time.perf_counter(), time.process_time()

    def __call__(self, phase: str) -> None:
        if self.timings is not None:
            now, cpu = time.perf_counter(), time.process_time()
            self.timings[phase] = self.timings.get(phase, 0.0) + now - self.t
            self.timings[phase + "_cpu"] = self.timings.get(phase + "_cpu", 0.0) + cpu - self.c
            self.t, self.c = now, cpu


def _build_templates(cam, r_ext, groups: list[_Group]) -> tuple[list[dict], dict]:
    """Lattice marks and pixel weights of each group's template (one per group given), and the batch arrays
    ("dir", "W", "cone") the templates' arrays are consecutive slices of (the caster takes them as they are
    when a batch builds all its templates, instead of copying every ray's data once more)."""
    tlat = np.array([g.lat for g in groups], dtype=np.int64).reshape(-1, 4)
    size = tlat[:, 2] * tlat[:, 3]
    loff = np.concatenate([[0], np.cumsum(size)[:-1]]).astype(np.int64)
    lut = np.empty(int(size.sum()), np.int32)
    tcount = np.zeros(len(groups), np.int64)
    _mark_templates(tlat, loff, np.array([g.cb for g in groups], dtype=np.float64).reshape(-1, 3),
                    np.array([g.check for g in groups], dtype=np.bool_), cam.fx, cam.fy, cam.cx, cam.cy,
                    r_ext * r_ext, lut, tcount)
    K = np.array([len(g.views) for g in groups], dtype=np.int64)
    tview = np.concatenate([[0], np.cumsum(K)]).astype(np.int64)
    toff = np.concatenate([[0], np.cumsum(tcount)[:-1]]).astype(np.int64)
    wsize = tcount * K
    woff = np.concatenate([[0], np.cumsum(wsize)[:-1]]).astype(np.int64)
    tcell = np.empty(int(tcount.sum()), np.int32)
    npix = np.zeros(int(K.sum()), np.int64)
    vtmpl = np.repeat(np.arange(len(groups), dtype=np.int64), K)
    Ms = np.ascontiguousarray(np.concatenate([g.Ms for g in groups]))
    wins = np.ascontiguousarray(np.concatenate([g.win for g in groups]))
    # the weights are small whole numbers (pixels of one view nearest to one lattice ray: 1 or 2 for a roll),
    # exact in uint8 and read as the same float64 by the caster: a quarter of float32's memory, which every
    # batch maps and zeroes afresh (the kernel's system time); float32 again if one would pass 255
    for dt, cap in ((np.uint8, 255.0), (np.float32, np.inf)):
        W = np.zeros(int(wsize.sum()), dt)
        _fill_templates(tlat, loff, lut, tcount, toff, tview, vtmpl, woff, Ms, wins, cam.fx, cam.fy, cam.cx, cam.cy,
                        tcell, W, cap, npix)
        if not (npix < 0).any():
            break
    del lut
    d = np.empty((len(tcell), 3))
    _template_dirs(tlat, toff, tcount, tcell, float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy), d)
    cone_all = np.empty(len(tcell), np.int32)
    out = []
    for i, g in enumerate(groups):
        Wi = W[woff[i]:woff[i] + wsize[i]]
        di = d[toff[i]:toff[i] + tcount[i]]
        ncu = -(-int(tlat[i, 2]) // _CONE)
        nc = ncu * -(-int(tlat[i, 3]) // _CONE)
        cone, axis, chord = cone_all[toff[i]:toff[i] + tcount[i]], np.empty((nc, 3)), np.empty(nc)
        _bundle_cones(di, tcell[toff[i]:toff[i] + tcount[i]], int(tlat[i, 2]), _CONE, ncu, cone, axis, chord)
        out.append({"n": int(tcount[i]), "K": int(K[i]), "dir": di, "W": Wi, "cone": cone, "axis": axis,
                    "chord": chord, "npix": npix[tview[i]:tview[i + 1]]})
    return out, {"dir": d, "W": W, "cone": cone_all}


def _bundle_starts(vol, cam, center, r_ext, batch: list[_Group], tms: list[dict], gtmpl, R0s, t0s, march: bool):
    """Where each group's ray bundles start (see `_cone_starts`): offsets of the groups' bundles and the
    starts; without `march`, every bundle starts at its group's free start. R0s, t0s: the groups' base poses."""
    ncone = np.array([len(t["chord"]) for t in tms], dtype=np.int64)
    ctoff = np.concatenate([[0], np.cumsum(ncone)]).astype(np.int64)
    coff = np.concatenate([[0], np.cumsum(ncone[gtmpl])]).astype(np.int64)
    tfree = _free_start(vol, t0s, center, r_ext, np.array([g.check for g in batch], dtype=np.bool_))
    # no ray goes past the range or the volume's farthest corner
    corners = vol.origin + np.stack(np.meshgrid([0, 1], [0, 1], [0, 1]), -1).reshape(-1, 3) * vol.shape * vol.voxel_size
    tmax = np.minimum(np.linalg.norm(t0s[:, None] - corners[None], axis=2).max(axis=1), min(cam.max_range, 1e30))
    cstart = np.empty(int(coff[-1]))
    _cone_starts(vol.bricks, vol.block_code(), vol.shift, np.array(vol.shape, np.int64), vol.origin, vol.voxel_size,
                 gtmpl, R0s, t0s, tfree, np.maximum(tmax, tfree) if march else tfree, ctoff,
                 np.concatenate([t["axis"] for t in tms]), np.concatenate([t["chord"] for t in tms]), coff, cstart)
    return coff, cstart


def _cast_batch(vol, cam, center, radius, r_ext, flags, p_unknown, batch: list[_Group], cache: dict, out: ViewRays,
                progress_cb, tick) -> None:
    """Cast one batch of groups: build the templates not cached yet, trace every group's rays, sum per
    view. The cache keeps only this batch's templates afterwards (a sphere's one template lives on)."""
    through, optimistic, march = flags
    new: dict = {}
    for g in batch:
        if g.key not in cache and g.key not in new:
            new[g.key] = g
    whole = None
    if new:
        built, whole = _build_templates(cam, r_ext, list(new.values()))
        cache.update(zip(new, built))
        out.templates += len(new)
    keys = list(dict.fromkeys(g.key for g in batch))
    if len(new) < len(keys):
        whole = None  # some templates come from the cache: gather them
    for k in [k for k in cache if k not in set(keys)]:
        del cache[k]
    tid = {k: i for i, k in enumerate(keys)}
    tms = [cache[k] for k in keys]
    tcount = np.array([t["n"] for t in tms], dtype=np.int64)
    K = np.array([t["K"] for t in tms], dtype=np.int64)
    tview = np.concatenate([[0], np.cumsum(K)]).astype(np.int64)
    toff = np.concatenate([[0], np.cumsum(tcount)[:-1]]).astype(np.int64)
    woff = np.concatenate([[0], np.cumsum(tcount * K)[:-1]]).astype(np.int64)
    if whole is not None:  # every template new, built in key order: the batch arrays are the concatenations
        tdir, W, tcone = whole["dir"], whole["W"], whole["cone"]
    else:
        tdir = np.ascontiguousarray(np.concatenate([t["dir"] for t in tms]))
        W = np.concatenate([t["W"] for t in tms])
        tcone = np.concatenate([t["cone"] for t in tms])
    gtmpl = np.array([tid[g.key] for g in batch], dtype=np.int64)
    gcount = tcount[gtmpl]
    ray_off = np.concatenate([[0], np.cumsum(gcount)]).astype(np.int64)
    views = np.concatenate([g.views for g in batch])
    gview = np.concatenate([[0], np.cumsum([len(g.views) for g in batch])[:-1]]).astype(np.int64)
    R0s = np.ascontiguousarray(np.array([g.R0 for g in batch], dtype=np.float64))
    t0s = np.ascontiguousarray(np.array([g.t0 for g in batch], dtype=np.float64))
    n = int(ray_off[-1])
    tick("mark")
    acc = np.zeros((_LANES, 7, len(views)), np.float64)
    steps = np.zeros((_LANES, 3), np.int64)
    coff, cstart = _bundle_starts(vol, cam, center, r_ext, batch, tms, gtmpl, R0s, t0s, march)
    tick("march")
    _cast_lattice(vol.shape, vol.bricks, vol.block_code(), vol.shift, vol.origin, vol.voxel_size,
                  ray_off, gtmpl, toff, tdir, tview, woff, W, gview, R0s, t0s,
                  tcone, coff, cstart,
                  cam.min_range,
                  min(cam.max_range, 1e30), center, float(radius), bool(through), bool(optimistic), float(p_unknown),
                  _CHUNK, acc, steps)
    out.block_steps += int(steps[:, 0].sum())
    out.voxel_steps += int(steps[:, 1].sum())
    out.fine_steps += int(steps[:, 2].sum())
    tick("cast")
    tot = acc.sum(axis=0).T
    npix = np.concatenate([tms[tid[g.key]]["npix"] for g in batch])
    # every cast ray adds its pixel weights to exactly one of columns 0-3 and the weights are whole numbers
    # (exact in float64), so column 3 (unknown in S, not written by the caster) is what the others leave
    tot[:, 3] = npix - tot[:, :3].sum(axis=1)
    out.counts[views] = np.stack([tot[:, 0] + tot[:, 3], tot[:, 1], tot[:, 2]], axis=1).round().astype(np.int64)
    out.terms[views] = tot[:, 3:7]
    out.rays[views] = npix
    out.rays_cast += n
    tick("accumulate")
    if progress_cb:
        progress_cb(len(views))
