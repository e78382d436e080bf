"""One grasp optimisation (thesis eq. 7.4, or eq. 8.2 with obstacle parts) with scipy's SLSQP.

Variables: the palm position p (3) and a rotation vector w (3) applied after a start orientation R0
(R = R0 exp(w): no gimbal lock near the start). Cost: sum over the L points p_i of H of
(sqrt(a1 a2 a3) (F(p_i)^e1 - 1))^2, the eq. 7.4 residual in the F^e1 form the superquadric fit uses (close
to a radial distance; plain F - 1 explodes for box-like exponents). Inequalities (>= 0):
  support_plane   height of every L and V point above the plane (eq. 7.6 for all points, not only the lowest);
  cone:AXIS       hand axis . cone direction - cos(aperture) (eq. 7.10);
  obstacle:K      sqrt(a1 a2 a3)_K (F_K(v_i)^e1 - 1) for each of the V points v_i: every palm and finger point
                  outside part K (eq. 8.2 sums over the V points, which lets one point sit inside the part
                  while the others are far out; [ours] one constraint per point);
  facing          z_h . (target centre - p): the palm faces the target ([ours]: with L points on a half
                  ellipsoid the mirror pose, object behind the palm, is also a local minimum);
and the workspace box as bounds on p (eq. 7.7). A few starts around the target are solved (the thesis'
Ipopt is a local method too): short screening runs, then the most promising refined in warm-restarted legs
(`_refine`) until one converges. Gradients are central differences computed for all six variables in one
vectorised evaluation: forward differences left active constraints violated by ~1e-6, above SLSQP's
stopping tolerance, so runs at the optimum went on to their iteration limit (the 0.7 s worst cases).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

from kinfu_cli.grasp.constraints import AXES, GraspConstraints
from kinfu_cli.grasp.hand import HandModel
from kinfu_cli.segmentation.superquadric import _TINY, Superquadric, inside_outside_local

CONSTRAINT_TOL = 1e-4  # [code] constr_tol: a constraint value >= -CONSTRAINT_TOL is satisfied
_FD_STEP = 1e-6
# SLSQP stops when the cost changes by less than its `ftol` AND the constraint violations sum to less than it
SLSQP_ACC = 1e-9
REFINE_LEG = 20  # iterations per SLSQP leg of a refinement (`_refine`)
# gradients of the refinement: "central" differences of twelve poses in one vectorised `evaluate` (default),
# "forward" (six poses; they leave active constraints ~1e-6 violated, so SLSQP does not stop), or "analytic"
# (`_Problem.value_and_grad`, equal to 1e-8; in numpy 1.4x slower in the same process, benchmarks/bench_grasp.py:
# its ~40 small array operations cost more than one batch; a numba kernel of it is the next lever).
# The 6-iteration screening runs only rank the starts: forward differences are enough there.
GRADIENT = "central"
SCREEN_GRADIENT = "forward"


def _f_pow(points: np.ndarray, sq: Superquadric) -> np.ndarray:
    """F(points)^e1 - 1 (N,) for world points: < 0 inside, ~ relative radial distance outside."""
    F = inside_outside_local(sq.to_local(points), sq.size, sq.exponents)
    return np.power(np.maximum(F, 1e-300), sq.exponents[0]) - 1.0


def _f_pow_grad(points: np.ndarray, sq: Superquadric) -> tuple[np.ndarray, np.ndarray]:
    """F^e1 - 1 (N,) and its gradient (N, 3) w.r.t. the world points, analytic, in the log space of
    `inside_outside_local`: with U = |x/a1|^(2/e2), V = |y/a2|^(2/e2), T1 = (U + V)^(e2/e1), T2 = |z/a3|^(2/e1),
    F = T1 + T2 and d(F^e1)/dx = 2 F^e1 / F * T1 U / ((U + V) x), likewise y; d/dz = 2 F^e1 / F * T2 / z.
    U / x and T2 / z go to 0 at 0 since 2 / e > 1 for the exponents a fit allows (< 2)."""
    local = sq.to_local(points)
    a = np.asarray(sq.size, dtype=np.float64)
    e1, e2 = float(sq.exponents[0]), float(sq.exponents[1])
    lx = np.log(np.maximum(np.abs(local) / a, _TINY))
    lnU, lnV, lnT2 = 2.0 * lx[:, 0] / e2, 2.0 * lx[:, 1] / e2, 2.0 * lx[:, 2] / e1
    S0 = np.exp(lnU) + np.exp(lnV)
    S = np.maximum(S0, _TINY)
    T1, T2 = np.exp((e2 / e1) * np.log(S)), np.exp(lnT2)
    F = np.maximum(T1 + T2, _TINY)
    G = np.exp(e1 * np.log(F))
    ln_abs = lx + np.log(a)  # ln|x|, ln|y|, ln|z|
    sign = np.sign(local)
    k = 2.0 * G / F * (T1 + T2 > _TINY)  # where F or U + V is clamped, F is flat (as computed)
    d = np.empty_like(local)
    k1 = k * T1 / S * (S0 > _TINY)
    d[:, 0] = k1 * sign[:, 0] * np.exp(lnU - ln_abs[:, 0])
    d[:, 1] = k1 * sign[:, 1] * np.exp(lnV - ln_abs[:, 1])
    d[:, 2] = k * sign[:, 2] * np.exp(lnT2 - ln_abs[:, 2])
    return G - 1.0, d @ sq.rotation.T


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b for (N, 3) arrays (np.cross costs ~0.1 ms of overhead per call here)."""
    return np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                     a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)


def _right_jacobian(w: np.ndarray) -> np.ndarray:
    """J_r of SO(3) at the rotation vector w: exp(w + d) = exp(w) exp(J_r(w) d) to first order."""
    t = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if t < 1e-6:
        return np.eye(3) - 0.5 * K + K @ K / 6.0
    return np.eye(3) - (1.0 - np.cos(t)) / t ** 2 * K + (t - np.sin(t)) / t ** 3 * (K @ K)


@dataclass
class PartGrasp:
    """Result of `grasp_part`: the palm pose (R columns x_h, y_h, z_h; p palm centre), world metres."""

    rotation: np.ndarray
    position: np.ndarray
    converged: bool  # the optimiser succeeded and every constraint holds within CONSTRAINT_TOL
    cost: float  # eq. 7.4 (F^e1 form) at the solution
    overlap_rms: float  # RMS radial distance (m) of the L points to the target surface
    constraints: dict[str, float]  # name -> smallest value (>= 0 satisfied)
    active: list[str]  # constraints within CONSTRAINT_TOL of their bound
    obstacle_distance: float  # eq. 8.11: sum over obstacles k and V points of sqrt(a1 a2 a3)_k (F_k^e1 - 1)
    hand: HandModel  # after the lifting rule
    message: str
    seconds: float
    iterations: int
    starts: int
    violation: float = 0.0  # largest constraint violation (>= 0)
    extra: dict = field(default_factory=dict)

    def matrix(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.rotation
        T[:3, 3] = self.position
        return T


class _Problem:
    """Cost and constraints of one target for batches of candidate poses (vectorised over poses and points)."""

    def __init__(self, target: Superquadric, obstacles: list[Superquadric], hand: HandModel,
                 cons: GraspConstraints):
        self.target, self.obstacles, self.hand, self.cons = target, obstacles, hand, cons
        self.L = hand.l_points()
        self.V = hand.v_points()
        self.all_points = np.vstack([self.L, self.V])
        self.vol = float(np.sqrt(np.prod(target.size)))
        self.R0 = np.eye(3)
        self.gradient = GRADIENT
        self.names = (["support_plane"] * len(self.all_points) if cons.plane is not None else []) + \
            [f"cone:{c.axis}" for c in cons.cones] + \
            [f"obstacle:{k}" for k in range(len(obstacles)) for _ in range(len(self.V))] + ["facing"]
        self._key: bytes | None = None
        self._val: tuple | None = None

    def poses(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R = self.R0[None] @ Rotation.from_rotvec(X[:, 3:6]).as_matrix()
        return R, X[:, :3]

    def evaluate(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scaled cost (m,) = mean (F^e1 - 1)^2 over L, and constraint values (m, n_constraints)."""
        R, p = self.poses(X)
        m, nL = len(X), len(self.L)
        W = p[:, None, :] + np.matmul(self.all_points, R.transpose(0, 2, 1))  # (m, L + V, 3) world points
        r = _f_pow(W[:, :nL].reshape(-1, 3), self.target).reshape(m, nL)
        cost = np.mean(r ** 2, axis=1)
        cols = []
        if self.cons.plane is not None:
            cols.append(W @ self.cons.plane[:3] + self.cons.plane[3])
        for c in self.cons.cones:
            k = AXES.index(c.axis)
            cols.append((R[:, :, k] @ c.unit() - np.cos(np.radians(c.aperture_deg)))[:, None])
        if self.obstacles:
            Vw = W[:, nL:]
            for ob in self.obstacles:
                cols.append(np.sqrt(np.prod(ob.size)) * _f_pow(Vw.reshape(-1, 3), ob).reshape(m, -1))
        cols.append(np.einsum("mi,mi->m", R[:, :, 2], self.target.center - p)[:, None])
        return cost, np.concatenate(cols, axis=1)

    def value_and_grad(self, x: np.ndarray) -> tuple:
        """Cost, its gradient (6,), constraint values (n,) and their Jacobian (n, 6) at one pose x, analytic.

        A hand point a (hand frame) lands at W = p + R a with R = R0 exp(w); dW/dp = I and, with J_r the right
        Jacobian of SO(3), dW/dw = -R [a]x J_r, so a world gradient g of a function of W pulls back to
        J_r^T (a x R^T g) on w."""
        p, w = x[:3], x[3:6]
        R = self.R0 @ Rotation.from_rotvec(w).as_matrix()
        J = _right_jacobian(w)
        A, nL = self.all_points, len(self.L)
        W = p + A @ R.T

        def pull(a: np.ndarray, g: np.ndarray) -> np.ndarray:  # rows [dp | dw] for world gradients g at a
            return np.hstack([g, _cross(a, g @ R) @ J])

        r, dr = _f_pow_grad(W[:nL], self.target)
        cost = float(np.mean(r ** 2))
        grad = (2.0 / nL) * (r @ pull(self.L, dr))
        vals, jacs = [], []
        if self.cons.plane is not None:
            n = self.cons.plane[:3]
            vals.append(W @ n + self.cons.plane[3])
            jacs.append(pull(A, np.broadcast_to(n, A.shape)))
        for c in self.cons.cones:
            e = np.eye(3)[AXES.index(c.axis)]
            vals.append(np.array([R[:, AXES.index(c.axis)] @ c.unit() - np.cos(np.radians(c.aperture_deg))]))
            jacs.append(np.hstack([np.zeros((1, 3)), _cross(e[None], (R.T @ c.unit())[None]) @ J]))
        for ob in self.obstacles:
            s = np.sqrt(np.prod(ob.size))
            f, df = _f_pow_grad(W[nL:], ob)
            vals.append(s * f)
            jacs.append(s * pull(self.V, df))
        d = self.target.center - p
        vals.append(np.array([R[:, 2] @ d]))
        jacs.append(np.hstack([-R[:, 2][None], _cross(np.array([[0.0, 0.0, 1.0]]), (R.T @ d)[None]) @ J]))
        return cost, grad, np.concatenate(vals), np.vstack(jacs)

    def _batch(self, x: np.ndarray) -> tuple:
        key = x.tobytes()
        if key != self._key:
            if self.gradient == "analytic":
                self._key, self._val = key, self.value_and_grad(x)
            elif self.gradient == "forward":  # seven poses in one batch
                c, g = self.evaluate(np.vstack([x, x + _FD_STEP * np.eye(6)]))
                self._key, self._val = key, (c[0], (c[1:] - c[0]) / _FD_STEP, g[0], (g[1:] - g[0]).T / _FD_STEP)
            else:  # central differences, thirteen poses in one batch
                E = _FD_STEP * np.eye(6)
                c, g = self.evaluate(np.vstack([x, x + E, x - E]))
                h = 2 * _FD_STEP
                self._key, self._val = key, (c[0], (c[1:7] - c[7:]) / h, g[0], (g[1:7] - g[7:]).T / h)
        return self._val

    def fun(self, x):
        return self._batch(x)[0]

    def jac(self, x):
        return self._batch(x)[1]

    def con(self, x):
        return self._batch(x)[2]

    def con_jac(self, x):
        return self._batch(x)[3]


def _support(sq: Superquadric, a: np.ndarray) -> float:
    """Extent of the superquadric's bounding box along unit direction a (from its centre)."""
    return float(np.sum(sq.size * np.abs(sq.rotation.T @ a)))


def _frame(approach: np.ndarray, across: np.ndarray) -> np.ndarray | None:
    """Rotation with z = approach and y = `across` made perpendicular to it; None when they are parallel."""
    z = approach / np.linalg.norm(approach)
    y = across - (across @ z) * z
    if np.linalg.norm(y) < 1e-6:
        return None
    y /= np.linalg.norm(y)
    return np.stack([np.cross(y, z), y, z], axis=1)


def start_poses(target: Superquadric, cons: GraspConstraints, n_starts: int, toward: np.ndarray | None
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """(R0, palm position) starts: approaches from above and along the target's horizontal axes (both
    ways), H's long axis along the target's longest axis or across it; those meeting the cones first,
    then those whose approach points away from `toward` (the workspace centre: the hand comes from there)."""
    up = cons.plane[:3] if cons.plane is not None else np.array([0.0, 0.0, 1.0])
    axes = [target.rotation[:, i] for i in np.argsort(-target.size)]
    approaches = [-up]
    for ax in axes:
        h = ax - (ax @ up) * up
        if np.linalg.norm(h) > 0.3:
            approaches += [h / np.linalg.norm(h), -h / np.linalg.norm(h)]
    for c in cons.cones:  # a cone on the approach axis: start on its axis
        if c.axis == "z":
            approaches.insert(0, c.unit())
    if toward is not None and np.linalg.norm(target.center - toward) > 1e-6:
        a = target.center - toward
        approaches.append(a / np.linalg.norm(a))
    cands = []
    for a in approaches:
        for across in (axes[0], axes[1], axes[2], up, np.cross(up, a)):
            R = _frame(a, across)
            if R is None:
                continue
            cone_margin = min([R[:, AXES.index(c.axis)] @ c.unit() - np.cos(np.radians(c.aperture_deg))
                               for c in cons.cones] or [1.0])
            p = target.center - _support(target, a) * a
            away = 0.0 if toward is None else float(a @ (target.center - toward)) / max(
                np.linalg.norm(target.center - toward), 1e-9)
            cands.append((min(cone_margin, 0.0), away, R, p))
    cands.sort(key=lambda c: (-c[0], -c[1]))
    out, seen = [], []
    for _, _, R, p in cands:
        if any(np.allclose(R, S, atol=1e-3) for S in seen):
            continue
        seen.append(R)
        out.append((R, p))
        if len(out) >= n_starts:
            break
    return out


def _run(prob: _Problem, R0: np.ndarray, x0: np.ndarray, bounds, max_iter: int, gradient: str | None = None
         ) -> tuple:
    """One SLSQP run from (R0, x0): (rank, R0, x, ok, constraint values, message, iterations); rank sorts
    feasible converged runs first, then by violation, then by cost. gradient: as GRADIENT (its default)."""
    prob.R0, prob._key, prob.gradient = R0, None, gradient or GRADIENT
    res = minimize(prob.fun, x0, jac=prob.jac, method="SLSQP", bounds=bounds,
                   constraints=[{"type": "ineq", "fun": prob.con, "jac": prob.con_jac}],
                   options={"maxiter": max_iter, "ftol": SLSQP_ACC})
    x = res.x
    cost, g = prob.evaluate(x[None])
    viol = float(max(0.0, -g[0].min()))
    ok = bool(res.success) and viol <= CONSTRAINT_TOL and bool(np.all(np.isfinite(x)))
    if bounds is not None:
        ok = ok and all(b[0] - 1e-9 <= v <= b[1] + 1e-9 for b, v in zip(bounds[:3], x[:3]))
    return ((not ok, viol, float(cost[0])), R0, x.copy(), ok, g[0], str(res.message),
            int(res.nit))


def _refine(prob: _Problem, R0: np.ndarray, x0: np.ndarray, bounds, max_iter: int) -> tuple:
    """SLSQP to convergence in legs of at most REFINE_LEG iterations (max_iter in all), each leg warm-started
    from the last one's pose with the rotation re-based (R0 <- R0 exp(w), w <- 0) and a fresh Hessian
    estimate. [ours]: a run that reached the optimum but does not meet SLSQP's stopping test (e.g. an active
    constraint violated by more than its tolerance) restarts there instead of running to its limit."""
    used, run = 0, None
    while used < max_iter:
        leg = min(REFINE_LEG, max_iter - used)
        run = _run(prob, R0, x0, bounds, leg)
        used += run[6]
        if run[3] or run[6] < leg:  # converged, or SLSQP stopped for another reason than its limit
            break
        x = run[2]
        R0 = R0 @ Rotation.from_rotvec(x[3:6]).as_matrix()
        x0 = np.concatenate([x[:3], np.zeros(3)])
    return run[:6] + (used,)


def grasp_part(target: Superquadric, hand: HandModel, cons: GraspConstraints, obstacles: list[Superquadric] = (),
               *, lifting: bool = True, n_starts: int = 4, max_iter: int = 100, screen_iter: int = 6) -> PartGrasp:
    """The best feasible pose of `hand` on `target` over `n_starts` SLSQP runs; `converged` is False (and the
    pose only the least-violating attempt, not a grasp) when no run satisfies every constraint."""
    t0, c0 = time.perf_counter(), time.process_time()
    hand_used = hand.lifted(target.size, target.rotation, tuple(cons.cones)) if lifting else hand
    prob = _Problem(target, list(obstacles), hand_used, cons)
    bounds = None
    if cons.workspace is not None:
        lo, hi = cons.workspace.low, cons.workspace.high
        bounds = [(lo[i], hi[i]) for i in range(3)] + [(-np.pi, np.pi)] * 3
    toward = cons.workspace.center() if cons.workspace is not None else None
    best = None
    iters = 0
    starts = start_poses(target, cons, n_starts, toward)
    runs = []
    for R0, p0 in starts:  # short screening runs; only the most promising is run to convergence
        x0 = np.concatenate([p0, np.zeros(3)])
        if bounds is not None:
            x0[:3] = np.clip(x0[:3], [b[0] for b in bounds[:3]], [b[1] for b in bounds[:3]])
        runs.append(_run(prob, R0, x0, bounds, screen_iter, SCREEN_GRADIENT) if len(starts) > 1
                    else _refine(prob, R0, x0, bounds, max_iter))
    runs.sort(key=lambda r: (r[0][1] > CONSTRAINT_TOL, r[0][2]))
    order = list(runs)
    if len(starts) > 1:  # refine the best screened run; when it fails, the next ones, until one converges
        for _, R0, x, _, _, _, _ in runs:
            order.append(_refine(prob, R0, x, bounds, max_iter))
            if order[-1][3]:
                break
    for rank, R0, x, ok, g, message, nit in order:
        iters += nit
        if best is None or rank < best[0]:
            R = R0 @ Rotation.from_rotvec(x[3:6]).as_matrix()
            best = (rank, R, x[:3].copy(), ok, g, message, rank[2])
    (_, viol, _), R, p, ok, g, message, scaled = best
    values: dict[str, float] = {}
    for name, v in zip(prob.names, g):
        values[name] = min(values.get(name, np.inf), float(v))
    if cons.workspace is not None:
        lo, hi = np.asarray(cons.workspace.low), np.asarray(cons.workspace.high)
        for i, ax in enumerate("xyz"):
            values[f"workspace:{ax}_min"] = float(p[i] - lo[i])
            values[f"workspace:{ax}_max"] = float(hi[i] - p[i])
    active = sorted(k for k, v in values.items() if abs(v) <= CONSTRAINT_TOL * 10 and not k.startswith("facing"))
    Lw = p + prob.L @ R.T
    overlap = float(np.sqrt(np.mean(target.radial_distance(Lw) ** 2)))
    Vw = p + prob.V @ R.T
    obst = float(sum(np.sqrt(np.prod(ob.size)) * _f_pow(Vw, ob).sum() for ob in obstacles))
    return PartGrasp(R, p, ok, float(scaled * len(prob.L) * prob.vol ** 2), overlap, values, active, obst,
                     hand_used, str(message), time.perf_counter() - t0, iters, len(starts), viol,
                     {"cpu_seconds": time.process_time() - c0})
