"""Local refinement of MUPF candidates: Gauss-Newton on the point-to-surface distances (an ICP step with the
distance field's closest points, numba, many candidates in parallel), then a few steps on the exact mesh.

Why: the MAP particle of eq. 4.28 carries the spread of its UKF covariance (median 10-20 deg off on correct
trials), and the filter ends with several distinct basins alive; polishing the best-weighted ones and keeping
the lowest I_L (the thesis' own score, eq. 4.30 / Alg. 3) turns a near miss into the basin's minimum.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange
from numba.extending import register_jitable

from kinfu_cli.localization.ukf import expmap, point_distance


@njit(cache=True)
def _gn_step(t, R, ys, H, damping, t_out, R_out):
    """One damped Gauss-Newton step on r_k = |y_k - h_k| along n_k = (y_k - h_k)/|.|, rotating about the points'
    centroid c: h' = c + exp(w)(h - c) + dt. H (L, 3) are the closest points at (t, R)."""
    L = ys.shape[0]
    c = np.zeros(3)
    for k in range(L):
        for a in range(3):
            c[a] += ys[k, a] / L
    A = np.zeros((6, 6))
    b = np.zeros(6)
    J = np.empty(6)
    for k in range(L):
        d0, d1, d2 = ys[k, 0] - H[k, 0], ys[k, 1] - H[k, 1], ys[k, 2] - H[k, 2]
        r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if r < 1e-9:
            continue
        n0, n1, n2 = d0 / r, d1 / r, d2 / r
        g0, g1, g2 = H[k, 0] - c[0], H[k, 1] - c[1], H[k, 2] - c[2]
        J[0], J[1], J[2] = n0, n1, n2
        J[3], J[4], J[5] = g1 * n2 - g2 * n1, g2 * n0 - g0 * n2, g0 * n1 - g1 * n0
        for i in range(6):
            b[i] += J[i] * r
            for j in range(6):
                A[i, j] += J[i] * J[j]
    for i in range(6):
        A[i, i] += damping * (A[i, i] + 1e-12)
    x = np.linalg.solve(A, b)
    dR = np.empty((3, 3))
    expmap(x[3], x[4], x[5], dR)
    for a in range(3):
        s = 0.0
        for j in range(3):
            R_out[a, j] = dR[a, 0] * R[0, j] + dR[a, 1] * R[1, j] + dR[a, 2] * R[2, j]
            s += dR[a, j] * (t[j] - c[j])
        t_out[a] = s + c[a] + x[a]


#: the damping both refinements start from (Levenberg-Marquardt on the diagonal of J^T J)
_DAMPING = 1e-3


@register_jitable  # compiled into refine_field, plain Python in refine_exact
def _judge(cur, new, damping):
    """The damped loop's rule, one for the field and the exact mesh: a step that raises the mean distance is
    undone and the damping raised x10; one that does not is kept and the damping lowered x0.3 (to 1e-6 at
    least); the loop ends when a kept step gains less than 1e-7 m. Returns (keep, done, damping)."""
    if new > cur:
        return False, False, damping * 10.0
    return True, cur - new < 1e-7, max(damping * 0.3, 1e-6)


@njit(cache=True, parallel=True)
def refine_field(t, R, ys, iterations, lo, step, sdf, normals, index):
    """Gauss-Newton from every candidate (t (K, 3), R (K, 3, 3), updated in place) on the field; index[k] is the
    candidate's final mean distance. A step that raises the mean distance is undone and the damping raised."""
    L = ys.shape[0]
    for i in prange(t.shape[0]):
        H = np.empty((L, 3))
        c = np.empty(3)
        tn, Rn = np.empty(3), np.empty((3, 3))
        cur = 0.0
        for k in range(L):
            cur += point_distance(t[i], R[i], ys[k], lo, step, sdf, normals, H[k], c) / L
        damping = _DAMPING
        for _ in range(iterations):
            _gn_step(t[i], R[i], ys, H, damping, tn, Rn)
            Hn = np.empty((L, 3))
            new = 0.0
            for k in range(L):
                new += point_distance(tn, Rn, ys[k], lo, step, sdf, normals, Hn[k], c) / L
            keep, done, damping = _judge(cur, new, damping)
            if keep:
                t[i, :] = tn
                R[i, :, :] = Rn
                H[:, :] = Hn
                cur = new
                if done:
                    break
        index[i] = cur


def refine_exact(model, ys: np.ndarray, t: np.ndarray, R: np.ndarray, iterations: int = 5):
    """A few Gauss-Newton steps on the exact mesh (open3d's BVH) from one pose; returns (t, R, I_L)."""
    def closest(t_, R_):
        return model.exact_closest_points((ys - t_) @ R_) @ R_.T + t_

    H = closest(t, R)
    cur = float(np.linalg.norm(ys - H, axis=1).mean())
    tn, Rn = np.empty(3), np.empty((3, 3))
    damping = _DAMPING
    for _ in range(iterations):
        _gn_step(t, R, ys, H, damping, tn, Rn)
        Hn = closest(tn, Rn)
        new = float(np.linalg.norm(ys - Hn, axis=1).mean())
        keep, done, damping = _judge(cur, new, damping)
        if keep:
            t, R, H, cur = tn.copy(), Rn.copy(), Hn, new
            if done:
                break
    return t, R, cur


def _jacobian(points: np.ndarray, normals: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Point-to-plane rows [n, ((p - centre) x n) / radius]: the rotation in arc length on the model's radius, so
    translation and rotation directions compare in metres."""
    return np.hstack([normals, np.cross(points - centre, normals) / radius])


def pose_std(model, ys: np.ndarray, t: np.ndarray, R: np.ndarray, noise: float) -> np.ndarray:
    """How well the points pin the pose: the standard deviations (m, m, m, rad, rad, rad; about the points'
    centroid) of noise^2 (J^T J)^-1, J the point-to-plane Jacobian at (t, R). A direction no point constrains
    (a box seen on faces parallel to one axis slides along it) gets a huge value, however low I_L is.
    Directions that move no part of the whole surface (a dome's turn about its axis: a continuous symmetry)
    are left out: every pose along them is the same answer."""
    H = model.exact_closest_points((ys - t) @ R) @ R.T + t
    d = ys - H
    n = d / np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    centre, radius = ys.mean(0), model.diameter / 2
    J = _jacobian(H, n, centre, radius)
    sp, sn = model.sample_surface(2000, np.random.default_rng(0), with_normals=True)
    Jm = _jacobian(sp @ R.T + t, sn @ R.T, centre, radius)
    ev, V = np.linalg.eigh(Jm.T @ Jm / len(Jm))
    Q = V[:, ev > 1e-4 * ev.max()]  # the directions the surface itself constrains
    # the points' information along them; a direction they do not constrain at all (points on a line turn
    # freely about it) has eigenvalue 0, which a pseudo-inverse would make a zero spread: floor it instead, so
    # its spread comes out huge (a row of J has norm >= 1, so 1e-12 L is far below any real constraint)
    evp, W = np.linalg.eigh(Q.T @ (J.T @ J) @ Q)
    QW = Q @ W
    cov = (QW / np.maximum(evp, 1e-12 * len(ys))) @ QW.T * noise ** 2
    scale = np.r_[1.0, 1.0, 1.0, 1 / radius, 1 / radius, 1 / radius]
    std = np.sqrt(np.maximum(np.diag(cov), 0.0)) * scale
    std[3:] = np.minimum(std[3:], math.pi)  # a free turn: any angle, not thousands of radians
    return std
