"""The MUPF's unscented Kalman step against textbook facts: with a linear measurement the UKF correction equals
the Kalman filter exactly for any alpha, beta, kappa; the sigma points reproduce mean and covariance; the
rotation helpers agree with scipy; the MAP density does not split one pose over Euler aliases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinfu_cli.localization import ukf
from kinfu_cli.localization.mupf import MupfParameters


def _spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n) * 0.1


@pytest.mark.parametrize("alpha,beta,kappa", [(1.0, 2.0, 2.0), (1.0, 30.0, 2.0), (0.5, 2.0, 0.0), (0.2, 0.0, 3.0)])
def test_ukf_correction_equals_the_kalman_filter_for_a_linear_measurement(alpha, beta, kappa):
    rng = np.random.default_rng(int(beta * 10 + kappa))
    wm, wc, spread = MupfParameters(alpha=alpha, beta=beta, kappa=kappa).unscented_weights()
    assert wm.sum() == pytest.approx(1.0)
    for _ in range(5):
        P = _spd(rng, 6)
        x = rng.normal(size=6)
        A, b, y = rng.normal(size=(3, 6)), rng.normal(size=3), rng.normal(size=3)
        sig2 = 0.3
        D = np.empty((13, 6))
        ukf.sigma_offsets(P, spread, D)
        assert np.allclose(wm @ D, 0, atol=1e-12)  # the sigma mean is the state
        assert np.allclose(np.einsum("s,sa,sb->ab", wc, D, D), P, atol=1e-10)  # and their covariance is P
        H = (x + D) @ A.T + b
        dx, Pn = np.empty(6), np.empty((6, 6))
        ukf.ukf_correct(P, D, H, y, wm, wc, sig2, dx, Pn)
        S = A @ P @ A.T + sig2 * np.eye(3)
        K = P @ A.T @ np.linalg.inv(S)
        assert np.allclose(dx, K @ (y - A @ x - b), atol=1e-10)
        assert np.allclose(Pn, P - K @ S @ K.T, atol=1e-10)


def test_cholesky_floor_matches_numpy_and_survives_a_singular_matrix():
    rng = np.random.default_rng(1)
    P = _spd(rng, 6)
    L = np.empty((6, 6))
    ukf.cholesky_floor(P, L)
    assert np.allclose(L, np.linalg.cholesky(P), atol=1e-12)
    v = rng.normal(size=(6, 1))
    ukf.cholesky_floor(v @ v.T, L)  # rank one: floored, still finite and lower triangular
    assert np.all(np.isfinite(L)) and np.allclose(np.triu(L, 1), 0)


def test_rotation_helpers_agree_with_scipy():
    rng = np.random.default_rng(2)
    R = np.empty((3, 3))
    w = np.empty(3)
    for a in rng.uniform(-4, 4, (50, 3)):
        ukf.euler_zyx(a[0], a[1], a[2], R)
        assert np.allclose(R, Rotation.from_euler("ZYX", a).as_matrix(), atol=1e-12)
    vecs = list(Rotation.random(50, random_state=3).as_rotvec()) + [np.array([np.pi - 1e-7, 0, 0]),
                                                                   np.array([0, 1e-9, 0])]
    for v in vecs:
        ukf.expmap(v[0], v[1], v[2], R)
        assert np.allclose(R, Rotation.from_rotvec(v).as_matrix(), atol=1e-12)
        ukf.logmap(R, w)
        assert np.allclose(Rotation.from_rotvec(w).as_matrix(), R, atol=1e-6)


def test_map_density_joins_euler_aliases_and_local_twins():
    """Two particles at one pose whose Euler angles differ by 2 pi: the density at each counts both (EULER wraps
    the difference); the same in LOCAL, where the difference is the rotation between them."""
    n = 3
    t = np.zeros((n, 3))
    e = np.array([[0.1, 0.2, 0.3], [0.1 + 2 * np.pi, 0.2, 0.3 - 2 * np.pi], [2.0, -1.0, 0.5]])
    R = Rotation.from_euler("ZYX", e).as_matrix()
    chol = np.broadcast_to(np.eye(6) * 0.1, (n, 6, 6)).copy()
    log_w = np.log(np.full(n, 1 / 3))
    for mode in (ukf.EULER, ukf.LOCAL):
        out = np.empty(n)
        ukf.map_scores(mode, t, e, R, t, e, R, chol, log_w, out)
        assert out[0] == pytest.approx(out[1]) and out[0] > out[2] + 0.5
