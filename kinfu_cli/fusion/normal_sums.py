"""The sums ICP's Gauss-Newton steps solve, shared by the point-to-plane term (fusion.icp) and the photometric
term (fusion.photometric): both linearise a residual r in a small motion (rotation w, translation v) of a world
point p as r + (p x a) . w + a . v, with a the residual's gradient in world coordinates (the model normal; the
intensity gradient carried into the world), so each correspondence adds J = [p x a, a] to one 6x6 system. Both also move a data vertex into the world and
into another camera (the model's, the reference frame's) the same way (moved_vertex)."""

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


@njit(cache=True, inline="always")
def moved_vertex(vert, v, u, R, t, R_cw, t_cw):
    """Data vertex (v, u) (camera frame) moved by the pose (R, t) into the world, and into the camera (R_cw, t_cw:
    camera <- world): (ok, world x, y, z, camera x, y, z); ok False for a missing vertex (NaN)."""
    x0 = vert[v, u, 0]
    if not (x0 == x0):
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    x1 = vert[v, u, 1]
    x2 = vert[v, u, 2]
    px = R[0, 0] * x0 + R[0, 1] * x1 + R[0, 2] * x2 + t[0]
    py = R[1, 0] * x0 + R[1, 1] * x1 + R[1, 2] * x2 + t[1]
    pz = R[2, 0] * x0 + R[2, 1] * x1 + R[2, 2] * x2 + t[2]
    qx = R_cw[0, 0] * px + R_cw[0, 1] * py + R_cw[0, 2] * pz + t_cw[0]
    qy = R_cw[1, 0] * px + R_cw[1, 1] * py + R_cw[1, 2] * pz + t_cw[1]
    qz = R_cw[2, 0] * px + R_cw[2, 1] * py + R_cw[2, 2] * pz + t_cw[2]
    return True, px, py, pz, qx, qy, qz
