"""Vectorised EM for small full-covariance Gaussian mixtures (GMM-AS fits K = 1..~12 in 4-D).

Written in numpy rather than sklearn.GaussianMixture because GMM-AS needs the time-segment
initialisation of the paper (means and covariances of equal time slices), runs dozens of fits per
trajectory, and sklearn's per-fit overhead (validation, copies) dominates at N of a few hundred.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass
class Mixture:
    """weights (K,), means (K, D), covariances (K, D, D); log_likelihood is the total over samples."""

    weights: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    log_likelihood: float
    n_iter: int
    converged: bool

    def n_parameters(self) -> int:
        k, d = self.means.shape
        return int(k * d + k * d * (d + 1) // 2 + k - 1)

    def bic(self, n_samples: int) -> float:
        """Bayesian information criterion (lower is better): -2 log L + p log N."""
        return float(-2.0 * self.log_likelihood + self.n_parameters() * np.log(n_samples))


def _log_gauss(x: np.ndarray, means: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """(N, K) log densities of x (N, D) under K Gaussians."""
    d = x.shape[1]
    chol = np.linalg.cholesky(covs)  # (K, D, D)
    diff = x[None, :, :] - means[:, None, :]  # (K, N, D)
    # solve L z = diff^T for each component
    z = np.linalg.solve(chol, diff.transpose(0, 2, 1))  # (K, D, N)
    maha = np.einsum("kdn,kdn->kn", z, z)
    logdet = 2.0 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
    return (-0.5 * (maha + logdet[:, None] + d * LOG_2PI)).T


def _regularise(covs: np.ndarray, reg: np.ndarray) -> np.ndarray:
    covs = 0.5 * (covs + covs.transpose(0, 2, 1))
    covs[:, np.arange(covs.shape[1]), np.arange(covs.shape[1])] += reg
    return covs


def time_segment_init(x: np.ndarray, k: int, reg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The paper's initialisation (Lee et al. 2012): split the time span (last column) into k equal
    segments; each Gaussian starts at the sample mean and covariance of its segment."""
    t = x[:, -1]
    edges = np.linspace(t[0], t[-1], k + 1)
    label = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, k - 1)
    counts = np.bincount(label, minlength=k).astype(np.float64)
    if np.any(counts < 2):
        # too few samples in a slice: fall back to equal sample counts
        label = np.minimum((np.arange(len(t)) * k) // len(t), k - 1)
        counts = np.bincount(label, minlength=k).astype(np.float64)
    onehot = np.zeros((len(t), k))
    onehot[np.arange(len(t)), label] = 1.0
    means = onehot.T @ x / counts[:, None]
    diff = x[None, :, :] - means[:, None, :]
    covs = np.einsum("kn,knd,kne->kde", onehot.T, diff, diff) / counts[:, None, None]
    return counts / counts.sum(), means, _regularise(covs, reg)


@njit(cache=True)
def _em_loop(x, weights, means, covs, reg, max_iter, tol):
    """The EM iterations (numba): E-step with per-component Cholesky, M-step, variance floor `reg`."""
    n, d = x.shape
    k = weights.shape[0]
    logr = np.empty((n, k))
    prev = -np.inf
    ll = -np.inf
    it = 0
    converged = False
    for it in range(1, max_iter + 2):
        # E-step
        for j in range(k):
            chol = np.linalg.cholesky(covs[j])
            logdet = 0.0
            for a in range(d):
                logdet += 2.0 * np.log(chol[a, a])
            base = np.log(max(weights[j], 1e-300)) - 0.5 * (logdet + d * np.log(2.0 * np.pi))
            z = np.empty(d)
            for i in range(n):
                # forward substitution L z = x_i - mu_j
                maha = 0.0
                for a in range(d):
                    acc = x[i, a] - means[j, a]
                    for b in range(a):
                        acc -= chol[a, b] * z[b]
                    z[a] = acc / chol[a, a]
                    maha += z[a] * z[a]
                logr[i, j] = base - 0.5 * maha
        ll = 0.0
        for i in range(n):
            mx = logr[i, 0]
            for j in range(1, k):
                if logr[i, j] > mx:
                    mx = logr[i, j]
            s = 0.0
            for j in range(k):
                s += np.exp(logr[i, j] - mx)
            lse = mx + np.log(s)
            ll += lse
            for j in range(k):
                logr[i, j] = np.exp(logr[i, j] - lse)  # now responsibilities
        if it > max_iter or abs(ll - prev) < tol * n:
            converged = it <= max_iter
            break  # parameters are those that produced ll
        prev = ll
        # M-step
        for j in range(k):
            nk = 1e-12
            for i in range(n):
                nk += logr[i, j]
            weights[j] = nk / n
            for a in range(d):
                acc = 0.0
                for i in range(n):
                    acc += logr[i, j] * x[i, a]
                means[j, a] = acc / nk
            for a in range(d):
                for b in range(a, d):
                    acc = 0.0
                    for i in range(n):
                        acc += logr[i, j] * (x[i, a] - means[j, a]) * (x[i, b] - means[j, b])
                    covs[j, a, b] = acc / nk
                    covs[j, b, a] = acc / nk
                covs[j, a, a] += reg[a]
    return weights, means, covs, ll, it - 1, converged


def fit_em(x: np.ndarray, k: int, reg: np.ndarray, max_iter: int = 100, tol: float = 1e-4) -> Mixture:
    """EM for a K-component full-covariance GMM on x (N, D), started from `time_segment_init`.

    reg (D,) is added to the covariance diagonals after every M-step (variance floor, units of x²).
    Stops when the mean log-likelihood per sample improves by less than `tol`; the returned
    log-likelihood belongs to the returned parameters.
    """
    weights, means, covs = time_segment_init(x, k, reg)
    w, m, c, ll, it, conv = _em_loop(np.ascontiguousarray(x, dtype=np.float64), weights.copy(),
                                     np.ascontiguousarray(means), np.ascontiguousarray(covs),
                                     np.asarray(reg, dtype=np.float64), int(max_iter), float(tol))
    return Mixture(w, m, c, float(ll), int(it), bool(conv))


def fit_em_numpy(x: np.ndarray, k: int, reg: np.ndarray, max_iter: int = 100, tol: float = 1e-4) -> Mixture:
    """Reference numpy implementation of `fit_em` (stops one M-step later), for tests and the benchmark."""
    n = x.shape[0]
    weights, means, covs = time_segment_init(x, k, reg)
    prev = -np.inf
    converged = False
    it = 0
    ll = -np.inf
    for it in range(1, max_iter + 1):
        lg = _log_gauss(x, means, covs) + np.log(np.maximum(weights, 1e-300))[None, :]
        mx = lg.max(axis=1, keepdims=True)
        lse = mx[:, 0] + np.log(np.exp(lg - mx).sum(axis=1))
        ll = float(lse.sum())
        resp = np.exp(lg - lse[:, None])  # (N, K)
        nk = resp.sum(axis=0) + 10 * np.finfo(float).eps
        weights = nk / n
        means = resp.T @ x / nk[:, None]
        diff = x[None, :, :] - means[:, None, :]
        covs = _regularise(np.einsum("nk,knd,kne->kde", resp, diff, diff) / nk[:, None, None], reg)
        if abs(ll - prev) < tol * n:
            converged = True
            break
        prev = ll
    # final likelihood for the returned parameters
    lg = _log_gauss(x, means, covs) + np.log(np.maximum(weights, 1e-300))[None, :]
    mx = lg.max(axis=1, keepdims=True)
    ll = float((mx[:, 0] + np.log(np.exp(lg - mx).sum(axis=1))).sum())
    return Mixture(weights, means, covs, ll, it, converged)
