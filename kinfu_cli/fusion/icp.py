"""Projective point-to-plane ICP, KinectFusion's tracker (Newcombe et al. 2011, section 3.5), in numba.

Data: the frame's depth, bilateral-filtered, as a pyramid of vertex and normal maps in the camera frame
(level l halves level l-1 by averaging the 2x2 pixels that agree with the first valid one). Model: the
volume's vertex and normal maps ray cast from one pose (fusion.raycast.band_raycast). Each data vertex, moved
by the current pose estimate, is projected into the model image; the model pixel it falls on is its
correspondence (no search), kept when the two points are within max_distance and their normals within
max_angle. Each iteration solves the 6x6 normal equations of the point-to-plane error linearised around the
current pose (parallel over pixel rows, one partial sum per row chunk) and applies the small motion found, a
rotation vector turned into a matrix by OpenCV's Rodrigues, to the left of the pose. Coarse-to-fine: the coarse levels
converge from further, the finest pins the pose.

The system's condition number (largest over smallest eigenvalue of the 6x6 matrix) is returned: a scene that
constrains a direction poorly (a flat wall: sliding along it costs nothing) has a huge one, and a pose found
along such a direction is a guess.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np
from numba import njit, prange

from kinfu_cli.core.camera import scaled_intrinsics
from kinfu_cli.fusion.normal_sums import N_SUMS, add_correspondence, moved_vertex
from kinfu_cli.fusion.photometric import FULL_WIDTH as PHOTO_FULL_WIDTH
from kinfu_cli.fusion.photometric import IntensityLevel, PhotometricReference, photometric_rows

# KinFu's bilateral filter for tracking: range sigma 3 cm, space sigma 4.5 px
BILATERAL_SIGMA_M = 0.03
BILATERAL_SIGMA_PX = 4.5
# two neighbouring pixels further apart in depth than this (m, per metre of depth) do not share a surface:
# no normal across a depth edge, no averaging across it when halving the image
EDGE_JUMP_PER_M = 0.04
# the pose is taken as converged when one iteration moves it less than this (rad, m)
CONVERGED = 1e-6


@dataclass
class DataLevel:
    """One pyramid level of the frame: vertices and normals (H, W, 3) float32 in the camera frame (NaN: none;
    None on levels below the pyramid's `first`, which only carry depth), depth (H, W) float32 (0: none) and the
    intrinsics of this level."""
    depth: np.ndarray
    vertices: np.ndarray | None
    normals: np.ndarray | None
    K: np.ndarray

    @property
    def n_valid(self) -> int:
        return int(np.count_nonzero(self.depth > 0))


@dataclass
class IcpResult:
    T_world_camera: np.ndarray
    inliers: int  # correspondences at the finest level, at the returned pose
    valid: int  # data vertices at the finest level
    rmse: float  # point-to-plane residual RMS of the inliers (m)
    condition: float  # condition number of the finest level's 6x6 system (inf: singular)
    iterations: int

    @property
    def fitness(self) -> float:
        """Share of the frame's vertices (finest level) with a model correspondence."""
        return self.inliers / self.valid if self.valid else 0.0


def data_pyramid(depth: np.ndarray, K: np.ndarray, n_levels: int, min_depth: float, max_depth: float,
                 bilateral: bool = True, first: int = 0, timing: dict | None = None) -> list[DataLevel]:
    """Vertex / normal maps of the depth image at full, half, quarter ... resolution (finest first); levels
    below `first` (finer than the tracker uses) carry only their depth. timing: seconds added under "filter"
    and "pyramid"."""
    import cv2  # heavy: only when tracking

    t0 = time.perf_counter()
    d = np.asarray(depth, dtype=np.float32)
    d = np.where((d >= min_depth) & (d <= max_depth), d, np.float32(0))
    if bilateral:
        f = cv2.bilateralFilter(d, 5, BILATERAL_SIGMA_M, BILATERAL_SIGMA_PX)
        d = np.where(d > 0, f, np.float32(0)).astype(np.float32)
    t1 = time.perf_counter()
    levels = []
    Kl = np.asarray(K, dtype=np.float64)
    for lev in range(n_levels):
        if lev:
            d = _halve(d)
            Kl = scaled_intrinsics(Kl, 0.5)
        v, n = (None, None) if lev < first else \
            _vertex_normal_maps(d, Kl[0, 0], Kl[1, 1], Kl[0, 2], Kl[1, 2], EDGE_JUMP_PER_M)
        levels.append(DataLevel(d, v, n, Kl))
    if timing is not None:
        timing["filter"] = timing.get("filter", 0.0) + t1 - t0
        timing["pyramid"] = timing.get("pyramid", 0.0) + time.perf_counter() - t1
    return levels


@njit(cache=True, parallel=True)
def _halve(d):
    """Half-size depth: per 2x2 block the mean of the readings within an edge jump of its first valid one."""
    h, w = d.shape[0] // 2, d.shape[1] // 2
    out = np.zeros((h, w), dtype=np.float32)
    for v in prange(h):
        for u in range(w):
            ref = 0.0
            acc = 0.0
            n = 0
            for k in range(4):
                z = d[2 * v + (k >> 1), 2 * u + (k & 1)]
                if z <= 0.0:
                    continue
                if n == 0:
                    ref = z
                if abs(z - ref) <= EDGE_JUMP_PER_M * ref:
                    acc += z
                    n += 1
            if n:
                out[v, u] = acc / n
    return out


@njit(cache=True)
def _neighbours(d, r, c, dr, dc, jump):
    """Pixels (a, b) along (dr, dc) around (r, c) sharing its surface: itself and the next one, else the previous
    one and itself; (-1, -1) when neither."""
    h, w = d.shape
    z = d[r, c]
    lim = jump * z
    r1, c1 = r + dr, c + dc
    if r1 < h and c1 < w and d[r1, c1] > 0.0 and abs(d[r1, c1] - z) <= lim:
        return 0, 1
    r0, c0 = r - dr, c - dc
    if r0 >= 0 and c0 >= 0 and d[r0, c0] > 0.0 and abs(d[r0, c0] - z) <= lim:
        return -1, 0
    return -2, -2


@njit(cache=True, parallel=True)
def _vertex_normal_maps(d, fx, fy, cx, cy, jump):
    """Camera-frame vertices of the depth image and their normals (vertex_normals)."""
    h, w = d.shape
    vert = np.full((h, w, 3), np.nan, dtype=np.float32)
    for r in prange(h):
        for c in range(w):
            z = d[r, c]
            if z > 0.0:
                vert[r, c, 0] = (c - cx) / fx * z
                vert[r, c, 1] = (r - cy) / fy * z
                vert[r, c, 2] = z
    return vert, vertex_normals(vert, d, 0.0, 0.0, 0.0, jump)


@njit(cache=True, parallel=True)
def vertex_normals(vert, d, ox, oy, oz, jump):
    """Normals of a vertex map from the neighbouring pixels (right and below, else left and above), facing the
    camera at (ox, oy, oz) (the vertices' frame); NaN where a neighbour is missing or across a depth edge. d: the
    pixels' depths (0: none), which decide the edges."""
    h, w = d.shape
    norm = np.full((h, w, 3), np.nan, dtype=np.float32)
    for r in prange(h):
        for c in range(w):
            if d[r, c] <= 0.0:
                continue
            ha, hb = _neighbours(d, r, c, 0, 1, jump)
            va, vb = _neighbours(d, r, c, 1, 0, jump)
            if ha == -2 or va == -2:
                continue
            ax = vert[r, c + hb, 0] - vert[r, c + ha, 0]
            ay = vert[r, c + hb, 1] - vert[r, c + ha, 1]
            az = vert[r, c + hb, 2] - vert[r, c + ha, 2]
            bx = vert[r + vb, c, 0] - vert[r + va, c, 0]
            by = vert[r + vb, c, 1] - vert[r + va, c, 1]
            bz = vert[r + vb, c, 2] - vert[r + va, c, 2]
            nx = ay * bz - az * by
            ny = az * bx - ax * bz
            nz = ax * by - ay * bx
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            if nn < 1e-12:
                continue
            if nx * (vert[r, c, 0] - ox) + ny * (vert[r, c, 1] - oy) + nz * (vert[r, c, 2] - oz) > 0.0:
                nn = -nn
            norm[r, c, 0] = nx / nn
            norm[r, c, 1] = ny / nn
            norm[r, c, 2] = nz / nn
    return norm


@njit(cache=True, inline="always")
def _project_vertex(vert, v, u, R, t, R_cw, t_cw, fx, fy, cx, cy, mw, mh):
    """Data vertex (v, u) moved by the pose (R, t) into the world, and the model pixel it projects to:
    (ok, world x, y, z, depth in the model camera, pixel column, row); ok False for a missing vertex, a point
    behind the model camera or outside its image."""
    ok, px, py, pz, qx, qy, qz = moved_vertex(vert, v, u, R, t, R_cw, t_cw)
    if not ok:
        return False, 0.0, 0.0, 0.0, 0.0, -1, -1
    if qz <= 0.0:
        return False, px, py, pz, qz, -1, -1
    mu = int(math.floor(fx * qx / qz + cx + 0.5))
    mv = int(math.floor(fy * qy / qz + cy + 0.5))
    if mu < 0 or mv < 0 or mu >= mw or mv >= mh:
        return False, px, py, pz, qz, -1, -1
    return True, px, py, pz, qz, mu, mv


@njit(cache=True, inline="always")
def _associate(vert, norm, v, u, R, t, model_v, model_n, R_cw, t_cw, fx, fy, cx, cy, mw, mh, max_dist2, min_cos):
    """The projective correspondence of data pixel (v, u) at the pose (R, t): (ok, the moved vertex p, the model
    normal n, the point-to-plane residual n . (p - q)); ok False without a model point with a normal, further
    than max_dist2 (squared m), or with normals more than acos(min_cos) apart."""
    ok, px, py, pz, qz, mu, mv = _project_vertex(vert, v, u, R, t, R_cw, t_cw, fx, fy, cx, cy, mw, mh)
    if not ok:
        return False, px, py, pz, 0.0, 0.0, 0.0, 0.0
    nx = model_n[mv, mu, 0]
    a0 = norm[v, u, 0]
    if not (nx == nx and a0 == a0):
        return False, px, py, pz, 0.0, 0.0, 0.0, 0.0
    ny = model_n[mv, mu, 1]
    nz = model_n[mv, mu, 2]
    ex = px - model_v[mv, mu, 0]
    ey = py - model_v[mv, mu, 1]
    ez = pz - model_v[mv, mu, 2]
    if ex * ex + ey * ey + ez * ez > max_dist2:
        return False, px, py, pz, 0.0, 0.0, 0.0, 0.0
    a1 = norm[v, u, 1]
    a2 = norm[v, u, 2]
    # data normal in the world . model normal
    if ((R[0, 0] * a0 + R[0, 1] * a1 + R[0, 2] * a2) * nx + (R[1, 0] * a0 + R[1, 1] * a1 + R[1, 2] * a2) * ny
            + (R[2, 0] * a0 + R[2, 1] * a1 + R[2, 2] * a2) * nz) < min_cos:
        return False, px, py, pz, 0.0, 0.0, 0.0, 0.0
    return True, px, py, pz, nx, ny, nz, nx * ex + ny * ey + nz * ez


@njit(cache=True, inline="always")
def _accumulate_rows(acc, vert, norm, v0, v1, R, t, model_v, model_n, R_cw, t_cw, fx, fy, cx, cy, max_dist2,
                     min_cos):
    """Adds the point-to-plane normal-equation sums of data rows v0..v1-1 to acc (N_SUMS: the upper triangle of
    J^T J, J^T r, sum r^2, count; J = [p x n, n])."""
    w = vert.shape[1]
    mh, mw = model_v.shape[0], model_v.shape[1]
    J = np.empty(6)
    for v in range(v0, v1):
        for u in range(w):
            ok, px, py, pz, nx, ny, nz, r = _associate(vert, norm, v, u, R, t, model_v, model_n, R_cw, t_cw, fx, fy,
                                                        cx, cy, mw, mh, max_dist2, min_cos)
            if not ok:
                continue
            add_correspondence(acc, J, px, py, pz, nx, ny, nz, r)


@njit(cache=True, parallel=True, fastmath=True)
def _normal_equations(vert, norm, R, t, model_v, model_n, R_cw, t_cw, fx, fy, cx, cy, max_dist2, min_cos, gray,
                      ref_gray, ref_gx, ref_gy, ref_depth, R_rw, t_rw, dfx, dfy, dcx, dcy, photo_stride, nchunks):
    """Sums of the point-to-plane normal equations over the data vertices with a projective correspondence, and
    after them the photometric term's (fusion.photometric; every photo_stride-th pixel and row; photo_stride 0:
    none, zeros), in one parallel pass over row chunks (a pass each cost the coarse levels 2x). One kernel for
    both: a depth-only twin was another 8 s of compilation at set-up.

    vert, norm: data maps (camera frame); R, t: the pose estimate (world <- camera); model maps (world) ray cast
    from the pose (R_cw, t_cw: model camera <- world) with intrinsics fx, fy, cx, cy. Per chunk of rows its own
    partial sums (threads never share an accumulator), added up at the end.
    """
    h = vert.shape[0]
    out = np.zeros((nchunks, 2 * N_SUMS))
    step = (h + nchunks - 1) // nchunks
    for c in prange(nchunks):
        acc = np.zeros(N_SUMS)
        photo = np.zeros(N_SUMS)
        v0, v1 = c * step, min(h, (c + 1) * step)
        _accumulate_rows(acc, vert, norm, v0, v1, R, t, model_v, model_n, R_cw, t_cw, fx, fy, cx, cy, max_dist2,
                         min_cos)
        if photo_stride > 0:
            photometric_rows(photo, vert, gray, v0, v1, R, t, ref_gray, ref_gx, ref_gy, ref_depth, R_rw, t_rw, dfx,
                             dfy, dcx, dcy, photo_stride)
        out[c, :N_SUMS] = acc
        out[c, N_SUMS:] = photo
    return out.sum(axis=0)


@njit(cache=True)
def _system(sums):
    """(A, b) of the 6x6 normal equations from the N_SUMS row."""
    A = np.empty((6, 6))
    k = 0
    for i in range(6):
        for j in range(i, 6):
            A[i, j] = sums[k]
            A[j, i] = sums[k]
            k += 1
    return A, sums[21:27].copy()


@njit(cache=True)
def _rodrigues(wx, wy, wz):
    """Rotation matrix of the rotation vector (wx, wy, wz) (angle = its norm)."""
    th = math.sqrt(wx * wx + wy * wy + wz * wz)
    R = np.eye(3)
    if th < 1e-15:
        return R
    kx, ky, kz = wx / th, wy / th, wz / th
    c, s = math.cos(th), math.sin(th)
    C = 1.0 - c
    R[0, 0] = c + kx * kx * C
    R[0, 1] = kx * ky * C - kz * s
    R[0, 2] = kx * kz * C + ky * s
    R[1, 0] = ky * kx * C + kz * s
    R[1, 1] = c + ky * ky * C
    R[1, 2] = ky * kz * C - kx * s
    R[2, 0] = kz * kx * C - ky * s
    R[2, 1] = kz * ky * C + kx * s
    R[2, 2] = c + kz * kz * C
    return R


@njit(cache=True)
def _icp_level(vert, norm, T, model_v, model_n, R_cw, t_cw, fx, fy, cx, cy, max_dist2, min_cos, iterations,
               converged, min_correspondences, nchunks, photo_weight, photo_share, gray, ref_gray, ref_gx, ref_gy,
               ref_depth, R_rw, t_rw, dfx, dfy, dcx, dcy):
    """Up to `iterations` Gauss-Newton steps of one pyramid level from the pose T (world <- camera, updated in
    place), in one call (no Python between the iterations). Returns (steps taken,
    whether the last one moved the pose less than `converged`, the last sums: they stand for the sums at the
    returned pose when it converged). photo_weight > 0: the photometric term (fusion.photometric) against the
    reference level (gray .. t_rw; dfx .. dcy the data level's intrinsics) is added to the system with that
    weight, lowered so that it adds at most photo_share of the point-to-plane term's information on the
    translation (the trace of its 3x3 block); the sums returned are the point-to-plane ones alone (fitness,
    residual, condition)."""
    sums = np.zeros(N_SUMS)
    for it in range(iterations):
        R = np.ascontiguousarray(T[:3, :3])
        t = np.ascontiguousarray(T[:3, 3])
        stride = 0 if photo_weight <= 0.0 else (1 if vert.shape[1] <= PHOTO_FULL_WIDTH else 2)
        both = _normal_equations(vert, norm, R, t, model_v, model_n, R_cw, t_cw, fx, fy, cx, cy, max_dist2, min_cos,
                                 gray, ref_gray, ref_gx, ref_gy, ref_depth, R_rw, t_rw, dfx, dfy, dcx, dcy, stride,
                                 nchunks)
        sums = both[:N_SUMS].copy()
        if sums[28] < min_correspondences:
            return it, False, sums
        A, b = _system(sums)
        if photo_weight > 0.0:
            Ap, bp = _system(both[N_SUMS:])
            w = photo_weight
            tp = Ap[3, 3] + Ap[4, 4] + Ap[5, 5]
            if tp > 0.0:  # at most photo_share of the depth term's information on the translation
                w = min(w, photo_share * (A[3, 3] + A[4, 4] + A[5, 5]) / tp)
            A = A + w * Ap
            b = b + w * bp
        xi = _solve6(A, -b)
        if not np.all(np.isfinite(xi)):
            return it, False, sums
        step = np.eye(4)
        step[:3, :3] = _rodrigues(xi[0], xi[1], xi[2])
        step[0, 3], step[1, 3], step[2, 3] = xi[3], xi[4], xi[5]
        T[:, :] = step @ T
        if (math.sqrt(xi[0] ** 2 + xi[1] ** 2 + xi[2] ** 2) < converged
                and math.sqrt(xi[3] ** 2 + xi[4] ** 2 + xi[5] ** 2) < converged):
            return it + 1, True, sums
    return iterations, False, sums


@njit(cache=True)
def _solve6(A, b):
    """x with A x = b by Gaussian elimination with partial pivoting (NaN when A is singular)."""
    M = A.copy()
    x = b.copy()
    n = 6
    for c in range(n):
        p = c
        for r in range(c + 1, n):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if M[p, c] == 0.0:
            x[:] = np.nan
            return x
        if p != c:
            for k in range(n):
                M[c, k], M[p, k] = M[p, k], M[c, k]
            x[c], x[p] = x[p], x[c]
        for r in range(c + 1, n):
            f = M[r, c] / M[c, c]
            for k in range(c, n):
                M[r, k] -= f * M[c, k]
            x[r] -= f * x[c]
    for c in range(n - 1, -1, -1):
        acc = x[c]
        for k in range(c + 1, n):
            acc -= M[c, k] * x[k]
        x[c] = acc / M[c, c]
    return x


def _condition(A: np.ndarray) -> float:
    ev = np.linalg.eigvalsh(A)
    return float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")


def projective_icp(levels: list[DataLevel], model_v: np.ndarray, model_n: np.ndarray, K_model: np.ndarray,
                   T_model: np.ndarray, T_init: np.ndarray, iterations=(10, 5, 4), max_distance=(0.10, 0.10, 0.10),
                   max_angle_deg: float = 30.0, min_correspondences: int = 6, converged: float = CONVERGED,
                   timing: dict | None = None, intensities: list[IntensityLevel] | None = None,
                   reference: PhotometricReference | None = None, photo_weight: float = 0.0,
                   photo_share: float = 1.0) -> IcpResult:
    """Pose (world <- camera) of the frame `levels` (finest first) against the model maps ray cast from T_model
    (world <- model camera) with K_model, from T_init. iterations and max_distance (m) per level, coarse to
    fine (the last entries are the finest level). A level stops early when an iteration moves the pose less than
    `converged` (rad and m). timing: seconds added per level ("icp WxH": its iterations, association, normal
    equations, solves and pose updates, in one numba call). intensities (the frame's, one per level of
    `levels`), reference (the previous frame's, the same sizes) and photo_weight > 0: the photometric term
    (fusion.photometric) joins the point-to-plane one with that weight, or less where it would add more than
    photo_share of the point-to-plane term's information on the translation."""
    if len(iterations) != len(max_distance) or len(iterations) > len(levels):
        raise ValueError("projective_icp: one iterations and max_distance entry per pyramid level")
    photo = photo_weight > 0 and intensities is not None and reference is not None
    if photo:
        Tr_inv = np.linalg.inv(np.asarray(reference.T_world_camera, dtype=np.float64))
        R_rw, t_rw = np.ascontiguousarray(Tr_inv[:3, :3]), np.ascontiguousarray(Tr_inv[:3, 3])
    else:
        R_rw, t_rw = np.eye(3), np.zeros(3)
    nothing = np.zeros((1, 1), dtype=np.float32)
    Tm_inv = np.linalg.inv(np.asarray(T_model, dtype=np.float64))
    R_cw, t_cw = np.ascontiguousarray(Tm_inv[:3, :3]), np.ascontiguousarray(Tm_inv[:3, 3])
    cam = (float(K_model[0, 0]), float(K_model[1, 1]), float(K_model[0, 2]), float(K_model[1, 2]))
    min_cos = math.cos(math.radians(max_angle_deg))
    T = np.array(T_init, dtype=np.float64)
    clock = {} if timing is None else timing
    used = 0
    n = len(iterations)
    sums, done = None, False
    for i in range(n):  # coarse to fine
        level = levels[n - 1 - i]
        h, w = level.depth.shape
        t0 = time.perf_counter()
        j = n - 1 - i
        if photo:
            ref = reference.levels[j]
            photo_args = (float(photo_weight), float(photo_share), intensities[j].gray, ref.gray, ref.gx, ref.gy,
                          reference.depths[j])
        else:
            photo_args = (0.0, 0.0, nothing, nothing, nothing, nothing, nothing)
        steps, done, sums = _icp_level(level.vertices, level.normals, T, model_v, model_n, R_cw, t_cw, *cam,
                                       max_distance[i] ** 2, min_cos, int(iterations[i]), float(converged),
                                       float(min_correspondences), 4 * numba.get_num_threads(), *photo_args,
                                       R_rw, t_rw, float(level.K[0, 0]), float(level.K[1, 1]),
                                       float(level.K[0, 2]), float(level.K[1, 2]))
        used += steps
        _add(clock, f"icp {w}x{h}", time.perf_counter() - t0)
    # the finest level at the returned pose: how many vertices found a correspondence, how well they fit (the
    # sums of its converged last iteration stand for them: the pose moved by less than `converged` since)
    if not done:
        t0 = time.perf_counter()
        sums = _normal_equations(levels[0].vertices, levels[0].normals, np.ascontiguousarray(T[:3, :3]),
                                 np.ascontiguousarray(T[:3, 3]), model_v, model_n, R_cw, t_cw, *cam,
                                 max_distance[-1] ** 2, min_cos, nothing, nothing, nothing, nothing, nothing, R_rw,
                                 t_rw, *cam, 0, 4 * numba.get_num_threads())[:N_SUMS]
        _add(clock, f"icp {levels[0].depth.shape[1]}x{levels[0].depth.shape[0]}", time.perf_counter() - t0)
    A, _ = _system(sums)
    count = int(sums[28])
    rmse = math.sqrt(sums[27] / count) if count else float("nan")
    cond = _condition(A) if count >= min_correspondences else float("inf")
    return IcpResult(T, count, levels[0].n_valid, rmse, cond, used)


def _add(clock: dict, phase: str, seconds: float) -> None:
    clock[phase] = clock.get(phase, 0.0) + seconds


def model_agreement(level: DataLevel, T_world_camera: np.ndarray, model_depth: np.ndarray, model_state: np.ndarray,
                    K_model: np.ndarray, T_model: np.ndarray, hit: int, occluded: int, tolerance: float) -> float:
    """The tracker's depth-agreement check against model maps already cast (from T_model): of the frame's
    vertices (this level) moved to T_world_camera whose model pixel has a surface (state `hit`, or `occluded`: a
    surface in front of the reading), the share within `tolerance` (m, along the model camera's z) of the model's
    depth; NaN when none has one."""
    Tm_inv = np.linalg.inv(np.asarray(T_model, dtype=np.float64))
    T = np.asarray(T_world_camera, dtype=np.float64)
    both, agree = _agreement_counts(level.vertices, np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]),
                                    model_depth, model_state, np.ascontiguousarray(Tm_inv[:3, :3]),
                                    np.ascontiguousarray(Tm_inv[:3, 3]), float(K_model[0, 0]), float(K_model[1, 1]),
                                    float(K_model[0, 2]), float(K_model[1, 2]), hit, occluded, float(tolerance))
    return agree / both if both else float("nan")


@njit(cache=True, parallel=True)
def _agreement_counts(vert, R, t, mdepth, mstate, R_cw, t_cw, fx, fy, cx, cy, hit, occluded, tol):
    h, w = vert.shape[0], vert.shape[1]
    mh, mw = mdepth.shape
    both = np.zeros(h, dtype=np.int64)
    agree = np.zeros(h, dtype=np.int64)
    for v in prange(h):
        for u in range(w):
            ok, px, py, pz, qz, mu, mv = _project_vertex(vert, v, u, R, t, R_cw, t_cw, fx, fy, cx, cy, mw, mh)
            if not ok:
                continue
            s = mstate[mv, mu]
            if s == hit:
                both[v] += 1
                if abs(qz - mdepth[mv, mu]) < tol:
                    agree[v] += 1
            elif s == occluded:
                both[v] += 1
    return both.sum(), agree.sum()
