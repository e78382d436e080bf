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

# KinFu's bilateral filter for tracking: range sigma 3 cm, space sigma 4.5 px
BILATERAL_SIGMA_M = 0.03
BILATERAL_SIGMA_PX = 4.5
# two neighbouring pixels further apart in depth than this (m, per metre of depth) do not share a surface:
# no normal across a depth edge, no averaging across it when halving the image
EDGE_JUMP_PER_M = 0.04
# the pose is taken as converged when one iteration moves it less than this (rad, m)
CONVERGED = 1e-6
N_SUMS = 29  # 21 upper-triangle entries of J^T J, 6 of J^T r, sum r^2, inlier count


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
    x0 = vert[v, u, 0]
    if not (x0 == x0):
        return False, 0.0, 0.0, 0.0, 0.0, -1, -1
    x1 = vert[v, u, 1]
    x2 = vert[v, u, 2]
    px = R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2 + t[0]
    py = R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2 + t[1]
    pz = R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2 + t[2]
    qx = R_cw[0, 0] * px + R_cw[0, 1] * py + R_cw[0, 2] * pz + t_cw[0]
    qy = R_cw[1, 0] * px + R_cw[1, 1] * py + R_cw[1, 2] * pz + t_cw[1]
    qz = R_cw[2, 0] * px + R_cw[2, 1] * py + R_cw[2, 2] * pz + t_cw[2]
    if qz <= 0.0:
        return False, px, py, pz, qz, -1, -1
    mu = int(math.floor(fx * qx / qz + cx + 0.5))
    mv = int(math.floor(fy * qy / qz + cy + 0.5))
    if mu < 0 or mv < 0 or mu >= mw or mv >= mh:
        return False, px, py, pz, qz, -1, -1
    return True, px, py, pz, qz, mu, mv


@njit(cache=True, parallel=True, fastmath=True)
def _normal_equations(vert, norm, R, t, model_v, model_n, R_cw, t_cw, fx, fy, cx, cy, max_dist2, min_cos, nchunks):
    """Sums of the point-to-plane normal equations over the data vertices with a projective correspondence.

    vert, norm: data maps (camera frame); R, t: the pose estimate (world <- camera); model maps (world) ray cast
    from the pose (R_cw, t_cw: model camera <- world) with intrinsics fx, fy, cx, cy. Per chunk of rows one row
    of N_SUMS sums (J = [p x n, n], r = n . (p - q), p the moved data vertex, q, n the model's): rows summed by
    the caller, so that threads never share an accumulator.
    """
    h, w = vert.shape[0], vert.shape[1]
    mh, mw = model_v.shape[0], model_v.shape[1]
    out = np.zeros((nchunks, N_SUMS))
    step = (h + nchunks - 1) // nchunks
    for c in prange(nchunks):
        acc = np.zeros(N_SUMS)
        J = np.zeros(6)
        for v in range(c * step, min(h, (c + 1) * step)):
            for u in range(w):
                ok, px, py, pz, qz, mu, mv = _project_vertex(vert, v, u, R, t, R_cw, t_cw, fx, fy, cx, cy, mw, mh)
                if not ok:
                    continue
                nx = model_n[mv, mu, 0]
                if not (nx == nx):
                    continue
                ny = model_n[mv, mu, 1]
                nz = model_n[mv, mu, 2]
                ex = px - model_v[mv, mu, 0]
                ey = py - model_v[mv, mu, 1]
                ez = pz - model_v[mv, mu, 2]
                if ex * ex + ey * ey + ez * ez > max_dist2:
                    continue
                a0 = norm[v, u, 0]
                if not (a0 == a0):
                    continue
                a1 = norm[v, u, 1]
                a2 = norm[v, u, 2]
                # data normal in the world . model normal
                if ((R[0, 0] * a0 + R[0, 1] * a1 + R[0, 2] * a2) * nx + (R[1, 0] * a0 + R[1, 1] * a1 + R[1, 2] * a2) * ny
                        + (R[2, 0] * a0 + R[2, 1] * a1 + R[2, 2] * a2) * nz) < min_cos:
                    continue
                r = nx * ex + ny * ey + nz * ez
                J[0] = py * nz - pz * ny
                J[1] = pz * nx - px * nz
                J[2] = px * ny - py * nx
                J[3] = nx
                J[4] = ny
                J[5] = nz
                k = 0
                for i in range(6):
                    for j in range(i, 6):
                        acc[k] += J[i] * J[j]
                        k += 1
                for i in range(6):
                    acc[21 + i] += J[i] * r
                acc[27] += r * r
                acc[28] += 1.0
        out[c] = acc
    return out


_UPPER = np.triu_indices(6)  # computed once: np.triu_indices costs more than the 6x6 solve


def _system(sums: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, int]:
    """(A, b, sum r^2, count) from the summed N_SUMS row."""
    A = np.zeros((6, 6))
    A[_UPPER] = sums[:21]
    A.T[_UPPER] = sums[:21]
    return A, sums[21:27], float(sums[27]), int(sums[28])


def _condition(A: np.ndarray) -> float:
    ev = np.linalg.eigvalsh(A)
    return float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")


def projective_icp(levels: list[DataLevel], model_v: np.ndarray, model_n: np.ndarray, K_model: np.ndarray,
                   T_model: np.ndarray, T_init: np.ndarray, iterations=(10, 5, 4), max_distance=(0.10, 0.10, 0.10),
                   max_angle_deg: float = 30.0, min_correspondences: int = 6, converged: float = CONVERGED,
                   timing: dict | None = None) -> IcpResult:
    """Pose (world <- camera) of the frame `levels` (finest first) against the model maps ray cast from T_model
    (world <- model camera) with K_model, from T_init. iterations and max_distance (m) per level, coarse to
    fine (the last entries are the finest level). A level stops early when an iteration moves the pose less than
    `converged` (rad and m). timing: seconds added per phase ("reduce WxH" per level: association and normal
    equations; "solve": the 6x6 solves and pose updates)."""
    import cv2  # heavy: only when tracking

    if len(iterations) != len(max_distance) or len(iterations) > len(levels):
        raise ValueError("projective_icp: one iterations and max_distance entry per pyramid level")
    Tm_inv = np.linalg.inv(np.asarray(T_model, dtype=np.float64))
    R_cw, t_cw = np.ascontiguousarray(Tm_inv[:3, :3]), np.ascontiguousarray(Tm_inv[:3, 3])
    fx, fy, cx, cy = (float(K_model[0, 0]), float(K_model[1, 1]), float(K_model[0, 2]), float(K_model[1, 2]))
    min_cos = math.cos(math.radians(max_angle_deg))
    nchunks = 4 * numba.get_num_threads()
    T = np.asarray(T_init, dtype=np.float64).copy()
    clock = {} if timing is None else timing
    used = 0

    def sums(level: DataLevel, dist: float) -> np.ndarray:
        t0 = time.perf_counter()
        out = _normal_equations(level.vertices, level.normals, np.ascontiguousarray(T[:3, :3]),
                                np.ascontiguousarray(T[:3, 3]), model_v, model_n, R_cw, t_cw, fx, fy, cx, cy,
                                dist * dist, min_cos, nchunks).sum(axis=0)
        key = f"reduce {level.depth.shape[1]}x{level.depth.shape[0]}"
        clock[key] = clock.get(key, 0.0) + time.perf_counter() - t0
        return out

    n = len(iterations)
    last = None  # the finest level's sums when its last iteration moved the pose by less than `converged`
    for i in range(n):  # coarse to fine
        level = levels[n - 1 - i]
        for _ in range(iterations[i]):
            s = sums(level, max_distance[i])
            t0 = time.perf_counter()
            A, b, _, count = _system(s)
            if count < min_correspondences:
                break
            try:
                xi = np.linalg.solve(A, -b)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(xi)):
                break
            used += 1
            step = np.eye(4)
            step[:3, :3] = cv2.Rodrigues(xi[:3])[0]  # scipy's Rotation: 8x slower for one vector
            step[:3, 3] = xi[3:]
            T = step @ T
            clock["solve"] = clock.get("solve", 0.0) + time.perf_counter() - t0
            if np.linalg.norm(xi[:3]) < converged and np.linalg.norm(xi[3:]) < converged:
                last = s if i == n - 1 else None
                break
    # the finest level at the returned pose: how many vertices found a correspondence, how well they fit (the
    # sums of its converged last iteration stand for them: the pose moved by less than `converged` since)
    A, b, r2, count = _system(sums(levels[0], max_distance[-1]) if last is None else last)
    rmse = math.sqrt(r2 / count) if count else float("nan")
    cond = _condition(A) if count >= min_correspondences else float("inf")
    return IcpResult(T, count, levels[0].n_valid, rmse, cond, used)


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
