"""The MUPF's per-particle work as numba kernels: the unscented Kalman step with the proximity measurement
model (thesis eqs. 4.9, 4.15-4.17), the proposal sample and its window likelihoods (eqs. 4.18-4.24), the MAP
density of eqs. 4.28-4.29, and distances of points to the model at many poses.

A pose is (t, R): p_world = R p_model + t. Its 6-D perturbation d = [dt, dr] is applied in one of two ways:
- EULER (the thesis' state x = [t, phi, theta, psi], intrinsic ZYX): x + d, R = Rz(phi) Ry(theta) Rx(psi);
- LOCAL (a rotation vector about the current estimate): t + dt, R' = exp(dr) R. Sigma points, corrections,
  proposal samples and the MAP's differences then live in the tangent space at each particle, so no Euler
  singularity (theta = +-pi/2) and no 2 pi / dual-angle aliases split one pose into several.
The building blocks `sigma_offsets` and `ukf_correct` are the textbook scaled unscented transform and Kalman
correction; tests check that with a linear measurement they equal the Kalman filter exactly.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from kinfu_cli.localization.distance_field import lookup

EULER, LOCAL = 0, 1
N_X = 6


@njit(cache=True)
def euler_zyx(a, b, c, R):
    """R = Rz(a) Ry(b) Rx(c) into R (3, 3)."""
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    R[0, 0], R[0, 1], R[0, 2] = ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc
    R[1, 0], R[1, 1], R[1, 2] = sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc
    R[2, 0], R[2, 1], R[2, 2] = -sb, cb * sc, cb * cc


@njit(cache=True)
def expmap(w0, w1, w2, R):
    """Rodrigues: the rotation by the vector (w0, w1, w2) into R (3, 3)."""
    th = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if th < 1e-12:
        a, b = 1.0, 0.5
    else:
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / (th * th)
    R[0, 0] = 1.0 - b * (w1 * w1 + w2 * w2)
    R[1, 1] = 1.0 - b * (w0 * w0 + w2 * w2)
    R[2, 2] = 1.0 - b * (w0 * w0 + w1 * w1)
    R[0, 1], R[1, 0] = -a * w2 + b * w0 * w1, a * w2 + b * w0 * w1
    R[0, 2], R[2, 0] = a * w1 + b * w0 * w2, -a * w1 + b * w0 * w2
    R[1, 2], R[2, 1] = -a * w0 + b * w1 * w2, a * w0 + b * w1 * w2


@njit(cache=True)
def logmap(R, out):
    """The rotation vector of R (3, 3) into out[0:3] (angle in [0, pi])."""
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    c = min(1.0, max(-1.0, c))
    th = math.acos(c)
    v0, v1, v2 = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]
    if th < 1e-6:
        out[0], out[1], out[2] = 0.5 * v0, 0.5 * v1, 0.5 * v2
        return
    if th > math.pi - 1e-4:  # near a half turn: the axis from the symmetric part
        d0 = math.sqrt(max(0.0, (R[0, 0] + 1.0) / 2.0))
        d1 = math.sqrt(max(0.0, (R[1, 1] + 1.0) / 2.0))
        d2 = math.sqrt(max(0.0, (R[2, 2] + 1.0) / 2.0))
        if d0 >= d1 and d0 >= d2:
            d1, d2 = (R[0, 1] + R[1, 0]) / (4.0 * d0), (R[0, 2] + R[2, 0]) / (4.0 * d0)
        elif d1 >= d2:
            d0, d2 = (R[0, 1] + R[1, 0]) / (4.0 * d1), (R[1, 2] + R[2, 1]) / (4.0 * d1)
        else:
            d0, d1 = (R[0, 2] + R[2, 0]) / (4.0 * d2), (R[1, 2] + R[2, 1]) / (4.0 * d2)
        n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        out[0], out[1], out[2] = th * d0 / n, th * d1 / n, th * d2 / n
        return
    f = th / (2.0 * math.sin(th))
    out[0], out[1], out[2] = f * v0, f * v1, f * v2


@njit(cache=True)
def cholesky_floor(A, L):
    """Lower Cholesky factor of the symmetric (n, n) A into L; pivots below 1e-12 x the largest diagonal are
    floored there (a covariance that lost definiteness in the update stays usable)."""
    n = A.shape[0]
    big = 0.0
    for i in range(n):
        big = max(big, A[i, i])
    floor = max(big, 1e-300) * 1e-12
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        L[j, j] = math.sqrt(max(s, floor))
        for i in range(j + 1, n):
            s = 0.5 * (A[i, j] + A[j, i])
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
        for i in range(j):
            L[i, j] = 0.0


@njit(cache=True)
def sigma_offsets(P, spread, D):
    """The 2n+1 sigma offsets of eq. 4.9 into D (2n+1, n): 0, +-columns of the Cholesky factor of spread P."""
    n = P.shape[0]
    L = np.empty((n, n))
    cholesky_floor(spread * P, L)
    for k in range(n):
        D[0, k] = 0.0
    for j in range(n):
        for k in range(n):
            D[1 + j, k] = L[k, j]
            D[1 + n + j, k] = -L[k, j]


@njit(cache=True)
def ukf_correct(P, D, H, y, wm, wc, sig2, dx, Pn):
    """Kalman correction from the sigma offsets D (2n+1, n) and their predicted measurements H (2n+1, p):
    y_bar = sum wm H; S = sum wc (H - y_bar)(H - y_bar)^T + sig2 I; Gamma = sum wc D (H - y_bar)^T;
    K = Gamma S^-1; dx = K (y - y_bar), Pn = P - K S K^T (symmetrised). (The sigma mean is the state itself: the
    offsets are symmetric.)"""
    n, p = D.shape[1], H.shape[1]
    ns = D.shape[0]
    ybar = np.zeros(p)
    for j in range(ns):
        for a in range(p):
            ybar[a] += wm[j] * H[j, a]
    S = sig2 * np.eye(p)
    G = np.zeros((n, p))
    for j in range(ns):
        for a in range(p):
            da = H[j, a] - ybar[a]
            for b in range(p):
                S[a, b] += wc[j] * da * (H[j, b] - ybar[b])
            for k in range(n):
                G[k, a] += wc[j] * D[j, k] * da
    K = G @ np.linalg.inv(S)
    r = y - ybar
    for k in range(n):
        dx[k] = 0.0
        for a in range(p):
            dx[k] += K[k, a] * r[a]
    KSK = K @ S @ K.T
    for a in range(n):
        for b in range(n):
            Pn[a, b] = P[a, b] - 0.5 * (KSK[a, b] + KSK[b, a])


@njit(cache=True)
def compose(mode, t, e, R, d, t_out, e_out, R_out, dR):
    """The pose (t, e, R) perturbed by d (6,) into (t_out, e_out, R_out) (module docstring: EULER / LOCAL);
    dR (3, 3) is scratch."""
    for k in range(3):
        t_out[k] = t[k] + d[k]
    if mode == EULER:
        for k in range(3):
            e_out[k] = e[k] + d[3 + k]
        euler_zyx(e_out[0], e_out[1], e_out[2], R_out)
    else:
        expmap(d[3], d[4], d[5], dR)
        for a in range(3):
            for b in range(3):
                R_out[a, b] = dR[a, 0] * R[0, b] + dR[a, 1] * R[1, b] + dR[a, 2] * R[2, b]
        for k in range(3):
            e_out[k] = e[k]


@njit(cache=True)
def point_distance(t, R, y, lo, step, sdf, normals, h, c):
    """Distance of the world point y to the model at (t, R); the closest surface point (world) into h (c (3,) is
    scratch)."""
    q0 = R[0, 0] * (y[0] - t[0]) + R[1, 0] * (y[1] - t[1]) + R[2, 0] * (y[2] - t[2])
    q1 = R[0, 1] * (y[0] - t[0]) + R[1, 1] * (y[1] - t[1]) + R[2, 1] * (y[2] - t[2])
    q2 = R[0, 2] * (y[0] - t[0]) + R[1, 2] * (y[1] - t[1]) + R[2, 2] * (y[2] - t[2])
    d = lookup(q0, q1, q2, lo, step, sdf, normals, c)
    for a in range(3):
        h[a] = R[a, 0] * c[0] + R[a, 1] * c[1] + R[a, 2] * c[2] + t[a]
    return d


@njit(cache=True, parallel=True)
def mupf_step(mode, sample, t, e, R, P, q_diag, y, window, expo, z, wm, wc, spread, sig2, lo, step, sdf, normals,
              t_bar, e_bar, R_bar, t_hat, e_hat, R_hat, P_new, chol, log_q, log_l, log_l_est):
    """One step of Alg. 2 for every particle i (in parallel): time update P + Q, sigma points, proximity
    measurement prediction h = closest surface point to y (eq. 4.17), Kalman correction (x_bar into t_bar,
    e_bar, R_bar), the proposal sample
    x_hat = x_bar (+) chol(P) z_i, its log proposal density (log_q, without the 2 pi constant), and the window's
    log likelihoods: plain sum (log_l, eq. 4.18) and weighted by expo (log_l_est, eq. 4.24). sample False: the
    particle is the UKF mean itself (x_hat = x_bar, log_q = 0) and z drives the random walk of eq. 4.12 instead,
    x_{t|t-1} = x_{t-1|t-1} + sqrt(Q) z, before the sigma points (the authors' released code)."""
    n_part = t.shape[0]
    ns = 2 * N_X + 1
    for i in prange(n_part):
        Pp = P[i].copy()
        for k in range(N_X):
            Pp[k, k] += q_diag[k]
        D = np.empty((ns, N_X))
        sigma_offsets(Pp, spread, D)
        H = np.empty((ns, 3))
        ts, es, Rs, dR, c = np.empty(3), np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
        tp, ep, Rp = np.empty(3), np.empty(3), np.empty((3, 3))
        if sample:
            tp[:] = t[i]
            ep[:] = e[i]
            Rp[:, :] = R[i]
        else:
            w = np.empty(N_X)
            for k in range(N_X):
                w[k] = math.sqrt(q_diag[k]) * z[i, k]
            compose(mode, t[i], e[i], R[i], w, tp, ep, Rp, dR)
        for j in range(ns):
            compose(mode, tp, ep, Rp, D[j], ts, es, Rs, dR)
            point_distance(ts, Rs, y, lo, step, sdf, normals, H[j], c)
        dx = np.empty(N_X)
        Pn = np.empty((N_X, N_X))
        ukf_correct(Pp, D, H, y, wm, wc, sig2, dx, Pn)
        tb, eb, Rb = t_bar[i], e_bar[i], R_bar[i]
        compose(mode, tp, ep, Rp, dx, tb, eb, Rb, dR)
        L = chol[i]
        cholesky_floor(Pn, L)
        P_new[i] = Pn
        if sample:
            s = L @ z[i]
            compose(mode, tb, eb, Rb, s, t_hat[i], e_hat[i], R_hat[i], dR)
            lq = 0.0
            for k in range(N_X):
                lq += -0.5 * z[i, k] * z[i, k] - math.log(L[k, k])
            log_q[i] = lq
        else:
            t_hat[i, :] = tb
            e_hat[i, :] = eb
            R_hat[i, :, :] = Rb
            log_q[i] = 0.0
        h = np.empty(3)
        acc, acc_est = 0.0, 0.0
        for k in range(window.shape[0]):
            d = point_distance(t_hat[i], R_hat[i], window[k], lo, step, sdf, normals, h, c)
            ll = -0.5 * d * d / sig2
            acc += ll
            acc_est += expo[k] * ll
        log_l[i] = acc
        log_l_est[i] = acc_est


@njit(cache=True)
def _wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=True, parallel=True)
def map_scores(mode, tc, ec, Rc, t, e, R, chol, log_w, out):
    """Eq. 4.29 in logs at candidate poses c: out[j] = log sum_i w_i N(c_j; x_i, P_i), the difference c_j (-) x_i
    taken in the particles' parameterisation (EULER: angles wrapped to (-pi, pi]; LOCAL: log(R_cj R_i^T)).
    O(N x candidates)."""
    n = t.shape[0]
    log_det = np.empty(n)
    for i in range(n):
        s = 0.0
        for k in range(N_X):
            s += math.log(chol[i, k, k])
        log_det[i] = s
    for j in prange(tc.shape[0]):
        d = np.empty(N_X)
        zv = np.empty(N_X)
        M = np.empty((3, 3))
        w = np.empty(3)
        terms = np.empty(n)
        for i in range(n):
            for k in range(3):
                d[k] = tc[j, k] - t[i, k]
            if mode == EULER:
                for k in range(3):
                    d[3 + k] = _wrap(ec[j, k] - e[i, k])
            else:
                for a in range(3):
                    for b in range(3):
                        M[a, b] = Rc[j, a, 0] * R[i, b, 0] + Rc[j, a, 1] * R[i, b, 1] + Rc[j, a, 2] * R[i, b, 2]
                logmap(M, w)
                d[3], d[4], d[5] = w[0], w[1], w[2]
            q = 0.0
            for k in range(N_X):  # forward substitution L z = d
                s = d[k]
                for c in range(k):
                    s -= chol[i, k, c] * zv[c]
                zv[k] = s / chol[i, k, k]
                q += zv[k] * zv[k]
            terms[i] = log_w[i] - 0.5 * q - log_det[i]
        peak = terms.max()
        out[j] = peak + math.log(np.exp(terms - peak).sum())


@njit(cache=True, parallel=True)
def pose_distances(t, R, points, lo, step, sdf, normals, out):
    """out[p, k] = distance of world point k to the model at pose p (t (P, 3), R (P, 3, 3))."""
    for p in prange(t.shape[0]):
        h, c = np.empty(3), np.empty(3)
        for k in range(points.shape[0]):
            out[p, k] = point_distance(t[p], R[p], points[k], lo, step, sdf, normals, h, c)
