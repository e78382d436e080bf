"""The sums ICP's Gauss-Newton steps solve, shared by the point-to-plane term (fusion.icp) and the photometric
term (fusion.photometric): both linearise a residual r in a small motion (rotation w, translation v) of a world
point p as r + (p x a) . w + a . v, with a the residual's gradient in world coordinates (the model normal; the
intensity gradient carried into the world), so each correspondence adds J = [p x a, a] to one 6x6 system."""

from __future__ import annotations

from numba import njit

N_SUMS = 29  # 21 upper-triangle entries of J^T J, 6 of J^T r, sum r^2, correspondence count


@njit(cache=True, inline="always")
def add_correspondence(acc, J, px, py, pz, ax, ay, az, r):
    """Adds one correspondence (world point p, gradient a, residual r) to the N_SUMS sums acc; J: a 6-float
    scratch array."""
    J[0] = py * az - pz * ay
    J[1] = pz * ax - px * az
    J[2] = px * ay - py * ax
    J[3] = ax
    J[4] = ay
    J[5] = az
    k = 0
    for i in range(6):
        for j in range(i, 6):
            acc[k] += J[i] * J[j]
            k += 1
    for i in range(6):
        acc[21 + i] += J[i] * r
    acc[27] += r * r
    acc[28] += 1.0
