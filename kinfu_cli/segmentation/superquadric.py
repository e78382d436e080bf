"""Superquadric fit to a (partial) segment point cloud (Vezzani 2019 thesis, ch. 7.1).

Model, in the superquadric's own frame (eq. 7.1, lambda_1..5):

    F(x, y, z) = ((x/a1)^(2/e2) + (y/a2)^(2/e2))^(e2/e1) + (z/a3)^(2/e1)

F < 1 inside, F = 1 on the surface, F > 1 outside. a1..a3 are the semi-axes (metres), e1 = lambda_4 and
e2 = lambda_5 the shape exponents (ellipsoid e1 = e2 = 1, box e1, e2 -> 0.1, cylinder along z:
e1 -> 0.1, e2 = 1), bounded to [0.1, 1.9] so the shape stays convex. The pose adds the centre
(lambda_6..8) and roll/pitch/yaw (lambda_9..11, R = Rz(yaw) Ry(pitch) Rx(roll), object -> world),
11 parameters in all, in that order.

Fit (eq. 7.2 in the Solina-Bajcsy form): minimise sum_i (sqrt(a1 a2 a3) (F(p_i)^e1 - 1))^2 with
`scipy.optimize.least_squares` (bounded trust-region reflective), an analytic, vectorised Jacobian, and
an initialisation from the oriented bounding box (PCA frame) tried with each box axis as the
superquadric's z axis. The F^e1 form is used instead of plain F - 1 because it is close to a
radial distance, so the fit is not dominated by points near the flat faces of box-like shapes.
Before fitting, outliers are removed (DBSCAN, keeping the largest cluster, as the thesis does) and the
cloud is subsampled uniformly.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.special import beta

from kinfu_cli.core.errors import ConfigError, KinfuError
from kinfu_cli.core.point_pairs import check_pair_count, pair_components

E_MIN = 0.1
E_MAX = 1.9
_TINY = 1e-12
# A fit whose largest side (2 x its largest semi-axis) exceeds this many times the largest side of its points'
# oriented box is not a shape of them (`oversize`). A partial view hides an object's depth, so the fit may rightly
# outgrow the box's thin side (0.03 -> 0.1 m on single views), not its largest. Of 211 fits (12 single views of
# objects scenes; 14 fused objects scenes, the fused sample and rgbd-tabletop-box) the right ones reached 1.28x
# (1.05x fused); the 3 above 2x were wrong (0.29 / 0.46 m on objects of 0.13 / 0.2 m, 0.76 m on a 0.35 m segment,
# its points a slab at one end), as was a 0.55 m disc, converged with residual 0, on a 0.19 m plate (2.9x).
OVERSIZE_FACTOR = 1.6
# A fit stopped at max_nfev is settled (`converged`) unless SETTLE_NFEV more evaluations, restarted from it, still
# move it: its semi-axes or centre by more than SETTLE_SIZE or its exponents by more than SETTLE_EXPONENT while
# lowering its cost by more than SETTLE_COST, or lower the cost by more than SETTLE_TAIL over their own last half.
# (scipy's `success` needs xtol = ftol = 1e-8, far below what changes a shape: it read "not converged" on 5 of the 7
# fits of rgbd-tabletop-box, 4 of which a run to max_nfev 2000 moved by < 1.4 mm and 0.2 % of their cost.) Of 53
# fits stopped at 60 (fused rgbd-tabletop-box, 5 of its frames, one frame; the fused demo; a household scene's
# multi-superquadric parts; synthetic partial views) a run to 2000 moved 44 by < 1 mm / 0.05 or < 1 % of their
# cost, the other 9 by 3.4-330 mm and 2.5-56 %; this test told all 53 apart (the settled fits' tails reached
# 0.05 %, the one moving fit within the tolerances, 0.6 mm and 1.1 %, had 0.7 %). Held out, 30 fits of the
# 7-Scenes redkitchen volume (6 moving): 29 right; the miss, read settled, a part the long run moved by 11 mm for
# 1.09 % of its cost.
SETTLE_NFEV = 20
SETTLE_SIZE = 1e-3
SETTLE_EXPONENT = 0.05
SETTLE_COST = 0.01
SETTLE_TAIL = 0.002


class SegmentError(KinfuError):
    """A segment is too small or degenerate (flat, collinear, non-finite) for a shape fit."""


def oversize(size: np.ndarray, box_extents: np.ndarray) -> float:
    """The fit's largest side (2 x its largest semi-axis `size`) over the largest side of its points' oriented
    box (`box_extents`, full sides); inf for a box of zero sides. Above OVERSIZE_FACTOR: not a fit of them."""
    largest = float(np.max(box_extents))
    return 2 * float(np.max(size)) / largest if largest > 0 else float("inf")


# --------------------------------------------------------------------------------------------- rotations
def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) @ Ry(pitch) @ Rx(roll) for rpy = (roll, pitch, yaw) in radians."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of `rpy_to_matrix` (pitch in [-pi/2, pi/2])."""
    R = np.asarray(R, dtype=np.float64)
    pitch = np.arcsin(np.clip(-R[2, 0], -1.0, 1.0))
    if abs(np.cos(pitch)) > 1e-9:
        roll = np.arctan2(R[2, 1], R[2, 2])
        yaw = np.arctan2(R[1, 0], R[0, 0])
    else:  # gimbal lock: put everything into yaw
        roll = 0.0
        yaw = np.arctan2(-R[0, 1], R[1, 1])
    return np.array([roll, pitch, yaw])


def _rpy_derivatives(rpy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """R and dR/droll, dR/dpitch, dR/dyaw."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    dRx = np.array([[0, 0, 0], [0, -sr, -cr], [0, cr, -sr]])
    dRy = np.array([[-sp, 0, cp], [0, 0, 0], [-cp, 0, -sp]])
    dRz = np.array([[-sy, -cy, 0], [cy, -sy, 0], [0, 0, 0]])
    return Rz @ Ry @ Rx, Rz @ Ry @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx


# ------------------------------------------------------------------------------------------ the model
@dataclass
class Superquadric:
    """Semi-axes `size` (3,) m, exponents (e1, e2), `center` (3,) m, `rotation` (3, 3) object -> world."""

    size: np.ndarray
    exponents: np.ndarray
    center: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    @classmethod
    def from_params(cls, params: np.ndarray) -> "Superquadric":
        """From the 11 parameters [a1, a2, a3, e1, e2, x, y, z, roll, pitch, yaw]."""
        p = np.asarray(params, dtype=np.float64).reshape(11)
        return cls(p[0:3].copy(), p[3:5].copy(), p[5:8].copy(), rpy_to_matrix(p[8:11]))

    @property
    def params(self) -> np.ndarray:
        """The 11 parameters [a1, a2, a3, e1, e2, x, y, z, roll, pitch, yaw] (thesis order)."""
        return np.concatenate([self.size, self.exponents, self.center, matrix_to_rpy(self.rotation)])

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) into the superquadric frame."""
        return (np.asarray(points, dtype=np.float64) - self.center) @ self.rotation

    def inside_outside(self, points: np.ndarray) -> np.ndarray:
        """F (N,) of world points: < 1 inside, 1 on the surface, > 1 outside."""
        return inside_outside_local(self.to_local(points), self.size, self.exponents)

    def radial_distance(self, points: np.ndarray) -> np.ndarray:
        """Approximate Euclidean distance (N,) of world points to the surface, along the ray from the centre."""
        local = self.to_local(points)
        F = inside_outside_local(local, self.size, self.exponents)
        r = np.linalg.norm(local, axis=1)
        return np.abs(r * (1.0 - np.power(np.maximum(F, _TINY), -self.exponents[0] / 2.0)))

    def sample_surface(self, n: int, rng: np.random.Generator | int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """About `n` world points on the surface and their outward unit normals (predicts the unseen side)."""
        return sample_superquadric(self, n, rng)

    def volume(self) -> float:
        """Enclosed volume (m^3), Jaklic et al.: 2 a1 a2 a3 e1 e2 B(e1/2 + 1, e1) B(e2/2, e2/2)."""
        e1, e2 = self.exponents
        return float(2.0 * np.prod(self.size) * e1 * e2 * beta(e1 / 2 + 1, e1) * beta(e2 / 2, e2 / 2))

    def to_json(self) -> dict:
        return {"size": self.size.tolist(), "exponents": self.exponents.tolist(), "center": self.center.tolist(),
                "rpy": matrix_to_rpy(self.rotation).tolist(), "rotation": self.rotation.tolist(),
                "params": self.params.tolist()}


def inside_outside_local(local: np.ndarray, size: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    """F of points already in the superquadric frame (eq. 7.1), computed in log space (no overflow)."""
    a = np.asarray(size, dtype=np.float64)
    e1, e2 = float(exponents[0]), float(exponents[1])
    lx = np.log(np.maximum(np.abs(local) / a, _TINY))  # ln|x/a|
    U = np.exp(2.0 * lx[:, 0] / e2)
    V = np.exp(2.0 * lx[:, 1] / e2)
    T1 = np.exp((e2 / e1) * np.log(np.maximum(U + V, _TINY)))
    T2 = np.exp(2.0 * lx[:, 2] / e1)
    return T1 + T2


def sample_superquadric(sq: Superquadric, n: int, rng: np.random.Generator | int | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Surface points and normals: random directions projected radially onto the surface.

    Directions are drawn per axis-scaled unit sphere, then moved along the ray to F = 1, which gives a
    fairly even cover (denser at box corners is acceptable for a prediction of the back side).
    """
    rng = np.random.default_rng(rng)
    d = rng.normal(size=(int(n), 3)) * sq.size
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    F = inside_outside_local(d, sq.size, sq.exponents)
    local = d * np.power(F, -sq.exponents[0] / 2.0)[:, None]
    grad = _grad_local(local, sq.size, sq.exponents)
    normals = grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), _TINY)
    return local @ sq.rotation.T + sq.center, normals @ sq.rotation.T


def _grad_local(local: np.ndarray, size: np.ndarray, exponents: np.ndarray) -> np.ndarray:
    a = np.asarray(size, dtype=np.float64)
    e1, e2 = float(exponents[0]), float(exponents[1])
    x = _nonzero(local)
    lx = np.log(np.abs(x) / a)
    U = np.exp(2 * lx[:, 0] / e2)
    V = np.exp(2 * lx[:, 1] / e2)
    A = np.maximum(U + V, _TINY)
    T1 = np.exp((e2 / e1) * np.log(A))
    T2 = np.exp(2 * lx[:, 2] / e1)
    return np.stack([2 * T1 * U / (e1 * A * x[:, 0]), 2 * T1 * V / (e1 * A * x[:, 1]), 2 * T2 / (e1 * x[:, 2])], 1)


def _nonzero(x: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    return np.where(np.abs(x) < eps, np.where(x < 0, -eps, eps), x)


# ------------------------------------------------------------------------- residual + Jacobian (vectorised)
def _residual_and_jacobian(theta: np.ndarray, pts: np.ndarray, want_jac: bool, cost: str = "radial"):
    """Residuals and, if asked, dr/dtheta (N, 11), for points `pts` (N, 3) in the fitting frame.

    cost "radial": r_i = |p_i| (1 - F_i^(-e1/2)), the distance from p_i to the surface along the ray
    through the centre (unbiased under noise, no preference for small or large shapes);
    cost "volume": r_i = sqrt(a1 a2 a3) (F_i^e1 - 1), the thesis' eq. 7.2 form (volume factor).
    """
    a = theta[0:3]
    e1, e2 = theta[3], theta[4]
    t = theta[5:8]
    R, dR0, dR1, dR2 = _rpy_derivatives(theta[8:11])
    q = pts - t
    p = _nonzero(q @ R)  # local coordinates
    lx = np.log(np.abs(p) / a)
    U = np.exp(2 * lx[:, 0] / e2)
    V = np.exp(2 * lx[:, 1] / e2)
    A = np.maximum(U + V, _TINY)
    lnA = np.log(A)
    lnT1 = (e2 / e1) * lnA
    lnT2 = 2 * lx[:, 2] / e1
    T1 = np.exp(lnT1)
    T2 = np.exp(lnT2)
    F = np.maximum(T1 + T2, _TINY)
    lnF = np.log(F)
    if cost == "radial":
        norm = np.sqrt(np.einsum("ij,ij->i", p, p))
        g = np.exp(-0.5 * e1 * lnF)  # F^(-e1/2)
        r = norm * (1.0 - g)
    else:
        G = np.exp(e1 * lnF)  # F^e1
        s = np.sqrt(a[0] * a[1] * a[2])
        r = s * (G - 1.0)
    if not want_jac:
        return r, None
    dFdp = np.stack([2 * T1 * U / (e1 * A * p[:, 0]), 2 * T1 * V / (e1 * A * p[:, 1]), 2 * T2 / (e1 * p[:, 2])], 1)
    dFda = -dFdp * p / a
    dFde1 = -(T1 * lnT1 + T2 * lnT2) / e1
    ulnu = U * (2 * lx[:, 0] / e2)
    vlnv = V * (2 * lx[:, 1] / e2)
    dFde2 = T1 / e1 * (lnA - (ulnu + vlnv) / A)
    J = np.empty((pts.shape[0], 11))
    if cost == "radial":
        drdF = norm * e1 * g / (2.0 * F)
        J[:, 0:3] = drdF[:, None] * dFda
        J[:, 3] = drdF * dFde1 + 0.5 * norm * g * lnF
        drdp = drdF[:, None] * dFdp + p * ((1.0 - g) / np.maximum(norm, _TINY))[:, None]
    else:
        drdF = s * e1 * G / F
        J[:, 0:3] = drdF[:, None] * dFda + r[:, None] / (2.0 * a[None, :])
        J[:, 3] = drdF * dFde1 + s * G * lnF
        drdp = drdF[:, None] * dFdp
    J[:, 4] = drdF * dFde2
    J[:, 5:8] = -drdp @ R.T  # p = R^T (x - t)  =>  dp/dt = -R^T
    for k, dR in enumerate((dR0, dR1, dR2)):
        J[:, 8 + k] = np.einsum("ij,ij->i", drdp, q @ dR)  # d(R^T q)/dangle = dR^T q
    return r, J


# -------------------------------------------------------------------------------------------- the fit
@dataclass
class SuperquadricFit:
    """Result of `fit_superquadric`: the shape, its residuals and what was used."""

    superquadric: Superquadric
    residual: float  # RMS of the approximate Euclidean point-to-surface distance (m), all kept points
    cost: float  # final least-squares cost on the fitted subset (0.5 * sum r^2)
    n_points: int  # points after the outlier filter
    n_fit: int  # points used by the optimiser
    n_outliers: int
    seconds: float
    success: bool  # converged: the optimiser's own test passed, or it stopped at max_nfev settled (`_settled`)
    not_converged_reason: str = ""  # why not, when success is False

    def to_json(self) -> dict:
        d = self.superquadric.to_json()
        d.update({"residual": self.residual, "cost": self.cost, "n_points": self.n_points, "n_fit": self.n_fit,
                  "n_outliers": self.n_outliers, "seconds": self.seconds, "converged": self.success})
        if not self.success:
            d["not_converged_reason"] = self.not_converged_reason
        return d


def _solve(pts_p: np.ndarray, x0: np.ndarray, lb: np.ndarray, ub: np.ndarray, cost: str, max_nfev: int,
           costs: list | None = None):
    """One bounded TRF run; residual and Jacobian are computed together and the Jacobian is cached. `costs`, when
    given, gets the cost of every evaluation."""
    cache: dict = {}

    def fun(th):
        r, J = _residual_and_jacobian(th, pts_p, True, cost)
        cache["x"], cache["J"] = th.copy(), J
        if costs is not None:
            costs.append(0.5 * float(r @ r))
        return r

    def jac(th):
        if "x" in cache and np.array_equal(cache["x"], th):
            return cache["J"]
        return _residual_and_jacobian(th, pts_p, True, cost)[1]

    return least_squares(fun, np.clip(x0, lb + 1e-9, ub - 1e-9), jac=jac, bounds=(lb, ub), method="trf",
                         x_scale="jac", max_nfev=max_nfev, xtol=1e-8, ftol=1e-8)


def _settled(pts_p: np.ndarray, res, lb: np.ndarray, ub: np.ndarray, cost: str, max_nfev: int) -> tuple[bool, str]:
    """Whether a run that stopped at max_nfev (`res`) had settled, and why not: scipy's `success` is False there
    even when further iterations would no longer change the shape (its xtol / ftol are far below what matters).
    SETTLE_NFEV more evaluations restarted from it tell (see SETTLE_NFEV); the fit itself is kept as it is."""
    costs: list[float] = []
    more = _solve(pts_p, res.x, lb, ub, cost, SETTLE_NFEV, costs)
    step = more.x - res.x
    size, exponent, centre = float(np.max(np.abs(step[0:3]))), float(np.max(np.abs(step[3:5]))), \
        float(np.linalg.norm(step[5:8]))
    base = max(float(res.cost), _TINY)
    drop = (float(res.cost) - float(more.cost)) / base
    best = np.minimum.accumulate(costs)
    tail = (best[len(best) // 2 - 1] - best[-1]) / base if more.status == 0 and len(best) >= 2 else 0.0
    stopped = f"stopped at max_nfev {max_nfev}"
    if drop > SETTLE_COST and (size > SETTLE_SIZE or centre > SETTLE_SIZE or exponent > SETTLE_EXPONENT):
        return False, (f"{stopped} short of its optimum: {SETTLE_NFEV} more evaluations lower its cost by "
                       f"{100 * drop:.1f} % and move its size by {1000 * size:.1f} mm, its centre by "
                       f"{1000 * centre:.1f} mm, its exponents by {exponent:.2f}")
    if tail > SETTLE_TAIL:
        return False, (f"{stopped} while still improving: {SETTLE_NFEV} more evaluations lower its cost by "
                       f"{100 * drop:.1f} %, {100 * tail:.2f} % in their last {SETTLE_NFEV - SETTLE_NFEV // 2}")
    return True, ""


def remove_outliers(points: np.ndarray, eps: float | None = None, min_points: int = 4) -> np.ndarray:
    """Keep the largest DBSCAN cluster (thesis pre-filter). `eps` defaults to 3x the median NN spacing. Its
    neighbour searches are bounded (core.point_pairs): SegmentError when the default eps would join too many
    pairs (only a segment of piled-up duplicate points does), ConfigError for a given eps."""
    pts = np.asarray(points, dtype=np.float64)
    if len(pts) < 3 * min_points:
        return np.ones(len(pts), dtype=bool)
    tree = cKDTree(pts)
    if eps is None:
        d, _ = tree.query(pts, k=2)
        spacing = float(np.median(d[:, 1]))
        eps = 3.0 * spacing + 1e-9
        check_pair_count(tree, eps, what="points of the segment", error=SegmentError,
                         hint=f"the superquadric fit's outlier filter searches within 3x their median spacing "
                              f"({spacing:.3g} m): a segment of piled-up duplicate points?")
    else:
        check_pair_count(tree, eps, what="points of the segment", parameter="eps",
                         hint="expected a radius near the points' spacing (default 3x their median spacing)")
    # DBSCAN via core points + connected components (same clusters as sklearn's DBSCAN on core points)
    nb = tree.query_ball_point(pts, r=eps, return_length=True)
    core = nb >= min_points
    if not core.any():
        return np.ones(len(pts), dtype=bool)
    pairs = tree.query_pairs(r=eps, output_type="ndarray")
    keep_pair = core[pairs[:, 0]] | core[pairs[:, 1]]
    pairs = pairs[keep_pair]
    n = len(pts)
    lab = pair_components(n, pairs)
    lab = np.where(core | np.isin(np.arange(n), pairs.ravel()), lab, -1)
    counts = np.bincount(lab[lab >= 0])
    return lab == int(np.argmax(counts))


def _initial_frames(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """OBB from PCA: centre (3,), axes (3, 3) columns, half-extents (3,)."""
    mu = pts.mean(axis=0)
    cov = np.cov((pts - mu).T)
    w, vecs = np.linalg.eigh(cov)
    vecs = vecs[:, ::-1]
    if np.linalg.det(vecs) < 0:
        vecs[:, 2] *= -1
    local = (pts - mu) @ vecs
    lo, hi = local.min(axis=0), local.max(axis=0)
    center = mu + vecs @ ((lo + hi) / 2)
    return center, vecs, (hi - lo) / 2


def fit_superquadric(points: np.ndarray, *, max_points: int = 200, outlier_filter: bool = True,
                     exponent_bounds: tuple[float, float] = (E_MIN, E_MAX), min_size: float = 0.002,
                     max_size: float | None = None, seed: int = 0, max_nfev: int = 60,
                     axis_candidates: int = 3, cost: str = "volume", screen_nfev: int = 10) -> SuperquadricFit:
    """Fit one superquadric to a segment's points (N, 3) metres.

    max_points: subsample for the optimiser (thesis 50; more points average the noise better);
    exponent_bounds: (lo, hi) for both e1 and e2 (thesis [0.1, 1.9]), or ((lo1, hi1), (lo2, hi2)) per
    exponent (the shape prior's eq. 7.11 bounds, `shape_prior.exponent_bounds`);
    axis_candidates: how many box axes to try as the superquadric z axis (1 = longest PCA axis only);
    cost: "volume" (thesis eq. 7.2 with the radial F^e1 form, default: the volume factor keeps partial
    views from growing into the unseen side) or "radial" (distance along the ray through the centre:
    unbiased but free to grow where nothing was observed);
    screen_nfev: evaluations per candidate axis before only the best candidate is refined.
    The fit is `success` (JSON 'converged') when the optimiser converged or stopped at max_nfev settled
    (`_settled`), else it says why (`not_converged_reason`).
    Raises SegmentError for fewer than 10 points, non-finite input or a flat/collinear segment.
    """
    t0 = time.perf_counter()
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise SegmentError(f"superquadric fit: points must be (N, 3), got shape {pts.shape}")
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 10:
        raise SegmentError(f"superquadric fit: segment has {len(pts)} finite points, need at least 10")
    if cost not in ("radial", "volume"):
        raise ConfigError(f"expected 'radial' or 'volume', got {cost!r}", parameter="cost")
    eb = np.asarray(exponent_bounds, dtype=np.float64)
    if eb.shape == (2,):
        eb = np.stack([eb, eb])  # the same (lo, hi) for e1 and e2
    if eb.shape != (2, 2) or not np.all((0.0 < eb[:, 0]) & (eb[:, 0] < eb[:, 1]) & (eb[:, 1] <= 2.0)):
        raise ConfigError(f"expected (lo, hi) or ((lo1, hi1), (lo2, hi2)) with 0 < lo < hi <= 2, got "
                          f"{exponent_bounds}", parameter="exponent_bounds")
    keep = remove_outliers(pts) if outlier_filter else np.ones(len(pts), dtype=bool)
    kept = pts[keep]
    n_out = int(len(pts) - len(kept))
    center0, axes, half = _initial_frames(kept)
    extent = float(2 * half.max())
    if half[1] < 1e-4 or extent < 1e-3:
        raise SegmentError(f"superquadric fit: degenerate segment (extents {2 * half} m): flat or collinear")
    rng = np.random.default_rng(seed)
    sub = kept if len(kept) <= max_points else kept[rng.choice(len(kept), max_points, replace=False)]
    # Work in the OBB frame: angles start at 0, far from gimbal lock.
    local = (sub - center0) @ axes
    max_sz = float(max_size) if max_size is not None else 1.5 * extent
    half_c = np.maximum(half, min_size * 1.5)
    lb = np.concatenate([[min_size] * 3, eb[:, 0], -np.full(3, extent), [-np.pi] * 3])
    ub = np.concatenate([[max_sz] * 3, eb[:, 1], np.full(3, extent), [np.pi] * 3])
    # Candidate z axes (longest box axis first); each gets a short screening run, the best is refined.
    perms = [(1, 2, 0), (0, 2, 1), (0, 1, 2)][: max(1, min(3, axis_candidates))]
    runs = []
    for perm in perms:
        P = np.eye(3)[:, perm]  # columns: SQ axes expressed in the OBB frame
        if np.linalg.det(P) < 0:
            P[:, 0] *= -1
        pts_p = local @ P
        a0 = np.clip(half_c[list(perm)], min_size * 1.5, max_sz * 0.9)
        e0 = np.clip(1.0, eb[:, 0] + 1e-3, eb[:, 1] - 1e-3)
        x0 = np.concatenate([a0, e0, np.zeros(3), np.zeros(3)])
        res = _solve(pts_p, x0, lb, ub, cost, screen_nfev if len(perms) > 1 else max_nfev)
        runs.append((float(res.cost), res, P, pts_p))
    runs.sort(key=lambda r: r[0])
    _, res, P, pts_p = runs[0]
    if len(perms) > 1 and res.status == 0:  # the screening run stopped at screen_nfev: refine it
        res = _solve(pts_p, res.x, lb, ub, cost, max_nfev)
    converged, why = bool(res.success), "" if res.success else f"the optimiser failed: {res.message}"
    if res.status == 0:  # the (refining) run stopped at max_nfev: settled, or still moving?
        converged, why = _settled(pts_p, res, lb, ub, cost, max_nfev)
    th = res.x
    R_local = rpy_to_matrix(th[8:11])
    R_world = axes @ P @ R_local
    center = center0 + axes @ P @ th[5:8]
    sq = Superquadric(th[0:3].copy(), th[3:5].copy(), center, R_world)
    dist = sq.radial_distance(kept)
    return SuperquadricFit(sq, float(np.sqrt(np.mean(dist ** 2))), float(res.cost), int(len(kept)), int(len(sub)),
                           n_out, time.perf_counter() - t0, converged, why)


def partial_view_cloud(sq: Superquadric, view_dirs: np.ndarray, n: int = 1500, noise: float = 0.002,
                       rng: np.random.Generator | int | None = None) -> np.ndarray:
    """Synthetic partial view: surface points of a (convex) superquadric that face at least one of the
    sensors at `sq.center + 0.8 m * view_dirs[k]`, with isotropic Gaussian noise `noise` (m).

    For a convex shape, facing the sensor is the same as being visible. Used by tests and benchmarks.
    """
    rng = np.random.default_rng(rng)
    dirs = np.atleast_2d(np.asarray(view_dirs, dtype=np.float64))
    pts, nrm = sq.sample_surface(4 * n, rng)
    vis = np.zeros(len(pts), dtype=bool)
    for d in dirs:
        cam = sq.center + 0.8 * d / np.linalg.norm(d)
        vis |= np.einsum("ij,ij->i", nrm, cam - pts) > 0
    pts = pts[vis][:n]
    return pts + rng.normal(scale=noise, size=pts.shape)


def arc_view_dirs(azimuth: float, n_views: int = 3, spread_deg: float = 60.0, elevation_deg: float = 45.0
                  ) -> np.ndarray:
    """Unit directions of `n_views` sensors on an arc (like a KinFu initial scan) around world z."""
    az = azimuth + np.radians(spread_deg) * (np.arange(n_views) - (n_views - 1) / 2)
    el = np.radians(elevation_deg)
    return np.stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.full(n_views, np.sin(el))], axis=1)


def parameter_errors(true: Superquadric, fit: Superquadric) -> dict:
    """Errors of a fit against the truth, independent of axis order and sign.

    size: max relative error of the semi-axes, sorted by length (a semi-axis permutation is the same
    shape); center: centre distance / largest true diameter; exponents: |e_fit - e_true| after
    matching the superquadric z axis (the axis e1 acts on); angle_deg: largest angle between matched
    axes, over axes whose semi-axis differs from the others by > 10 % (else the axis is arbitrary).
    """
    C = np.abs(true.rotation.T @ fit.rotation)
    perm = max(itertools.permutations(range(3)), key=lambda p: sum(C[i, p[i]] for i in range(3)))
    size_err = float(np.max(np.abs(np.sort(fit.size) - np.sort(true.size)) / np.sort(true.size)))
    center_err = float(np.linalg.norm(fit.center - true.center) / (2 * true.size.max()))
    distinct = [i for i in range(3)
                if all(abs(true.size[i] - true.size[j]) > 0.1 * true.size[i] for j in range(3) if j != i)]
    ang = [float(np.degrees(np.arccos(np.clip(C[i, perm[i]], -1, 1)))) for i in distinct]
    exp_err = np.abs(fit.exponents - true.exponents) if perm[2] == 2 else np.full(2, np.nan)
    return {"size": size_err, "center": center_err, "angle_deg": max(ang) if ang else 0.0,
            "exponents": exp_err.tolist()}
