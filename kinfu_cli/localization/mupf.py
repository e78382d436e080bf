"""The Memory Unscented Particle Filter (Vezzani 2019, Alg. 2): 6-DoF pose of a known static mesh from a
sequence of 3-D surface points, vectorised over particles and sigma points.

Each of N particles is a UKF over x = [t, Euler angles] (`mesh_model` convention) with the artificial random
walk x_t = x_{t-1} + w, w ~ N(0, Q) and the proximity measurement model y = h(x) + v, v ~ N(0, sigma_p^2 I),
h(x) the surface point closest to y with the object at x (eq. 4.17). After the UKF correction with the
current point, every particle draws x_hat ~ N(x_bar, P) and is weighted by the likelihood of the last m
points (the memory window, eqs. 4.18-4.20) over the proposal density; resampling starts after t0 steps.
The estimate is the MAP particle of eqs. 4.28-4.29 under the estimation weights of eq. 4.24, and I_L
(eq. 4.30) scores it without ground truth. By default (a departure, `refine`) the MAP particle and the best
distinct candidates are then polished on the points and the lowest I_L kept; `converged` asks the points to fit
at their noise level.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.memory import USABLE_FRACTION, available_bytes
from kinfu_cli.core.progress import progress
from kinfu_cli.core.volume_file import MAX_COORDINATE_M
from kinfu_cli.localization import ukf
from kinfu_cli.localization.mesh_model import MeshModel, matrix_pose, pose_matrix, pose_rotations
from kinfu_cli.localization.refine import pose_std, refine_exact, refine_field

N_X = 6
MIN_POINTS = 3  # three points fix a rigid pose of a generic surface; fewer leave a continuum of poses
# the unscented transform's beta (eq. 4.9: W0^(c) = lambda / (n + lambda) + 1 - alpha^2 + beta) weighs the centre
# sigma point in the covariances: 2 is the textbook value for a Gaussian, 30 the thesis'. Below 0 that weight can
# turn negative and the covariances indefinite (a crash in the Kalman gain); above 1000 it only adds overflow risk
MAX_BETA = 1000.0
# float64s a particle holds at the peak of a step (localize_mupf): state, covariance, its Cholesky factor, the UKF
# mean and the sample (~165), their copies at resampling (51) and the MAP candidates (~35), 8 bytes each; 1.8 kB
# measured (peak RSS, 5000 vs 20000 particles)
BYTES_PER_PARTICLE = 2048
# Seconds of filtering (`estimated_seconds`), measured on this project's 2-core machine with other work running (an
# idle machine is up to ~1.5x faster) on a 27 cm sample object (sample_data/tabletop obj1.ply), refine 0:
# - every step moves each particle's sigma points and samples (per particle and step), and weighs the points of its
#   memory window (per particle and window point): N = 700 took 10.7-21.7 s over L = 800 points (window 400),
#   55 s over 1600 (window 800), N = 1400 over 400 / 800 points 17.3 / 49 s, N = 2800 over 200 / 400 10.2 / 24.3 s,
#   N = 700 over 3000 points (refine 100) 220-241 s a model;
# - the MAP estimate (eq. 4.28) scores 2N candidates against N particles: N = 4000 / 8000 / 16000 over 10 points
#   took 1.4 / 5.0 / 24 s (quadratic);
# - polishing (refine 100) added under 1 s over 1600 points: left out.
SECONDS_PER_PARTICLE_STEP = 2.5e-5
SECONDS_PER_PARTICLE_WINDOW_POINT = 7e-8
SECONDS_PER_MAP_PAIR = 5e-8


@dataclass(frozen=True)
class MupfParameters:
    """Table 4.1 (simulation): Q, P0 (diagonals; m^2, rad^2), sigma_p^2 (m^2), the unscented transform's
    alpha, beta, kappa, N particles; window m (None: ceil(L/2), the choice of ch. 5) and t0 = 2 steps without
    resampling. Converged (`converged_rule`): I_L <= max_index and the 90th percentile of the point distances
    <= 5/3 max_index; max_index None: 1.5 x `noise`, the measurements' noise std (m). At the true pose I_L is
    about 0.8 noise (half-normal), p90 1.6 noise; wrong basins measured 2.8-8 mm after polishing at 2 mm noise.
    (The thesis' check I_L <= sigma_p = 1 cm passed about 20 wrong poses per shape: max_index=0.01.) A converged
    pose is also reported `ambiguous` when the points do not pin it (`pinned`, refine.pose_std).
    Measured departures, each with the value that restores the thesis (README, "Localisation"):
    - rotation "local": sigma points, corrections and proposal samples perturb the rotation by a rotation
      vector at the particle ("euler": the thesis' Euler-angle state, wrapped in the MAP differences);
    - divide_by_proposal False: eq. 4.18's division by N(x_hat; x_bar, P) (without the transition density of
      Alg. 1 that would cancel it) multiplies every weight by exp(|z|^2 / 2) det(P)^(1/2), noise unrelated to
      the fit that favours unconverged particles; without it more tuning trials succeeded (True: the thesis);
    - map_candidates "both": the MAP of eq. 4.28 is taken over the particles x_hat and their UKF means x_bar
      ("particles": x_hat only, the thesis);
    - literal_estimate_weights False: eq. 4.24's second division by the proposal density is dropped (Remark 1's
      derivation multiplies the weights of eq. 4.19 by the likelihood powers only).
    - refine > 0: the MAP estimate and the `refine` - 1 best-weighted distinct particles are polished by
      Gauss-Newton on the points, the `flips` best also turned half about the model's principal axes, and the
      lowest I_L wins (0: the MAP particle of eq. 4.28 as it is, the thesis); refine = 100, flips = 3 chosen
      on tuning seed 100 (20 trials per shape: 20/20 everywhere; flips 0 left 3 cleaner half-turns);
    proposal "mean" / resample_ess < 1 are the authors' released code (particle = UKF mean moved by the random
    walk of eq. 4.12; resampling only below an effective sample size of resample_ess N), measured worse here."""

    particles: int = 700
    window: int | None = None
    t0: int = 2
    alpha: float = 1.0
    beta: float = 30.0
    kappa: float = 2.0
    sigma_p2: float = 1e-4
    q_diag: tuple[float, ...] = (1e-5, 1e-5, 1e-5, 1e-4, 1e-4, 1e-4)
    p0_diag: tuple[float, ...] = (0.04, 0.04, 0.04, math.pi ** 2, (math.pi / 2) ** 2, math.pi ** 2)
    max_index: float | None = None
    rotation: str = "local"
    divide_by_proposal: bool = False
    map_candidates: str = "both"
    literal_estimate_weights: bool = False
    proposal: str = "sample"
    resample_ess: float = 1.0
    refine: int = 100
    refine_iterations: int = 15
    flips: int = 3
    noise: float = 0.002

    def check(self) -> None:
        check_number(self.particles, "particles", 1, integer=True)
        avail = available_bytes()
        if self.particles * BYTES_PER_PARTICLE > USABLE_FRACTION * avail:
            raise ConfigError(f"{self.particles} particles would need about "
                              f"{self.particles * BYTES_PER_PARTICLE / 1024**3:.1f} GB ({BYTES_PER_PARTICLE} bytes "
                              f"each; {avail / 1024**3:.1f} GB available): expected at most "
                              f"{int(USABLE_FRACTION * avail // BYTES_PER_PARTICLE)} (the thesis uses 700-1200)",
                              parameter="particles")
        if self.window is not None:
            check_number(self.window, "window", 1, integer=True)
        check_number(self.t0, "t0", 0, integer=True)
        check_number(self.alpha, "alpha", 0, low_open=True)
        check_number(self.beta, "beta", 0, MAX_BETA)
        if self.rotation not in ("local", "euler"):
            raise ConfigError(f"expected 'local' or 'euler', got {self.rotation!r}", parameter="rotation")
        if self.map_candidates not in ("both", "particles"):
            raise ConfigError(f"expected 'both' or 'particles', got {self.map_candidates!r}", parameter="map_candidates")
        if self.proposal not in ("sample", "mean"):
            raise ConfigError(f"expected 'sample' or 'mean', got {self.proposal!r}", parameter="proposal")
        check_number(self.resample_ess, "resample_ess", 0, 1)
        check_number(self.refine, "refine", 0, integer=True)
        check_number(self.refine_iterations, "refine_iterations", 0, integer=True)
        check_number(self.flips, "flips", 0, integer=True)
        # distances no larger than the data's own bound (farther is corrupt data; 1e308 overflowed the squares)
        check_number(self.noise, "noise", 0, MAX_COORDINATE_M, low_open=True, unit="m")
        check_number(self.sigma_p2, "sigma_p2", 0, MAX_COORDINATE_M ** 2, low_open=True, unit="m^2")
        if self.max_index is not None:
            check_number(self.max_index, "max_index", 0, MAX_COORDINATE_M, low_open=True, unit="m")
        for name in ("q_diag", "p0_diag"):
            vals = getattr(self, name)
            if len(vals) != N_X or not all(math.isfinite(v) and v >= 0 for v in vals):
                raise ConfigError(f"expected 6 finite non-negative variances, got {vals!r}", parameter=name)

    def unscented_weights(self) -> tuple[np.ndarray, np.ndarray, float]:
        """W^(m), W^(c) over the 2n+1 sigma points and the spread n + lambda (eq. 4.9)."""
        lam = self.alpha ** 2 * (N_X + self.kappa) - N_X
        wm = np.full(2 * N_X + 1, 1.0 / (2 * (N_X + lam)))
        wc = wm.copy()
        wm[0] = lam / (N_X + lam)
        wc[0] = lam / (N_X + lam) + (1 - self.alpha ** 2 + self.beta)
        return wm, wc, N_X + lam


def window_points(n_points: int, window: int | None) -> int:
    """Points the filter weighs over all its steps: step k weighs the last min(k, m) points (m: the window, None:
    ceil(L/2) as `localize_mupf` takes it), about 3/8 L^2 with the default window."""
    m = window if window is not None else max(1, math.ceil(n_points / 2))
    m = min(m, n_points)
    return m * (m + 1) // 2 + (n_points - m) * m


def estimated_seconds(params: MupfParameters, n_points: int) -> float:
    """Seconds `localize_mupf` is expected to take over n_points on this project's machine (the constants above):
    linear in the particles N and the points L through the steps, in N x the window points (~3/8 L^2), and
    quadratic in N through the MAP estimate."""
    n = params.particles
    return (SECONDS_PER_PARTICLE_STEP * n * n_points
            + SECONDS_PER_PARTICLE_WINDOW_POINT * n * window_points(n_points, params.window)
            + SECONDS_PER_MAP_PAIR * 2 * n * n)


# the weights and MAP candidates exactly as printed (eqs. 4.18, 4.24, 4.28)
PAPER_WEIGHTS = {"divide_by_proposal": True, "literal_estimate_weights": True, "map_candidates": "particles"}
# the estimate exactly as the thesis reports it: the MAP particle, no refinement of candidates
NO_REFINE = {"refine": 0, "flips": 0}


@dataclass
class MupfResult:
    """The MAP pose (vector and 4x4 model-to-world), its I_L (m), whether it passed `converged_rule`, the I_L of
    the MAP estimate after each step (`index_history`), the run time (s), the distances' 90th percentile, how well the points pin the pose (`pose_std`) and whether
    they leave it ambiguous (`pinned` fails)."""

    pose: np.ndarray
    index: float
    converged: bool
    max_index: float
    seconds: float
    window: int
    index_history: list[float] = field(default_factory=list)
    index_p90: float = float("nan")
    pose_std: np.ndarray | None = None
    ambiguous: bool = False

    @property
    def matrix(self) -> np.ndarray:
        return pose_matrix(self.pose)


def check_points(points: np.ndarray, source: str = "points") -> np.ndarray:
    """(L, 3) finite measurements within MAX_COORDINATE_M of the origin (farther is corrupt data, and the pose
    arithmetic loses its rotation there), at least MIN_POINTS of them."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ConfigError(f"{source}: expected (L, 3) points, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ConfigError(f"{source}: points are not finite")
    if pts.size and np.abs(pts).max() > MAX_COORDINATE_M:
        raise ConfigError(f"{source}: a coordinate of {np.abs(pts).max():g} m; expected points within "
                          f"{MAX_COORDINATE_M:g} m of the origin (in metres)")
    if len(pts) < MIN_POINTS:
        raise ConfigError(f"{source}: {len(pts)} points; localisation needs at least {MIN_POINTS}")
    return pts


def _initial_particles(x0: np.ndarray, params: MupfParameters, rng: np.random.Generator):
    """x_{0|0} ~ N(x0, P0) (Alg. 2 line 2) as positions, Euler angles and their rotation matrices."""
    x = x0 + rng.standard_normal((params.particles, N_X)) * np.sqrt(np.asarray(params.p0_diag))
    return np.ascontiguousarray(x[:, :3]), np.ascontiguousarray(x[:, 3:]), pose_rotations(x)


def _systematic_resample(log_w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices drawn with probability w (Alg. 2 line 29), by systematic sampling (lower variance than
    multinomial, the same expectation; the authors' code does the same)."""
    n = len(log_w)
    c = np.cumsum(np.exp(log_w))
    c[-1] = 1.0
    return np.minimum(np.searchsorted(c, (rng.random() + np.arange(n)) / n), n - 1)


def localize_mupf(model: MeshModel, points: np.ndarray, params: MupfParameters = MupfParameters(), *,
                  x0: np.ndarray | None = None, seed: int | None = 0, quiet: bool = True,
                  track_index: bool = False, observer=None) -> MupfResult:
    """Run Alg. 2 over `points` (L, 3, world frame, in measurement order) for `model`; x0 is the prior mean
    (the 6-D null vector by default, as in the thesis' tests). track_index computes I_L of the MAP estimate
    after every step (slower: an O(N^2) MAP per step). observer(step, t_hat, R_hat, log_w) sees the proposal
    samples and their normalised log weights after every step (diagnostics)."""
    params.check()
    ys = np.ascontiguousarray(check_points(points))
    L = len(ys)
    m = params.window if params.window is not None else max(1, math.ceil(L / 2))
    rng = np.random.default_rng(seed)
    n = params.particles
    wm, wc, spread = params.unscented_weights()
    mode = ukf.LOCAL if params.rotation == "local" else ukf.EULER
    q_diag = np.asarray(params.q_diag, dtype=np.float64)
    x0 = np.zeros(N_X) if x0 is None else np.asarray(x0, dtype=np.float64)
    model.build_field()
    f = model.field
    start = time.perf_counter()
    t, e, R = _initial_particles(x0, params, rng)
    P = np.broadcast_to(np.diag(params.p0_diag), (n, N_X, N_X)).copy()
    t_hat, e_hat, R_hat = np.empty_like(t), np.empty_like(e), np.empty_like(R)
    t_bar, e_bar, R_bar = np.empty_like(t), np.empty_like(e), np.empty_like(R)
    P_new, chol = np.empty_like(P), np.empty_like(P)
    log_q, log_l, log_l_est = np.empty(n), np.empty(n), np.empty(n)
    sig2 = params.sigma_p2
    log_w_prev = np.full(n, -math.log(n))
    history: list[float] = []
    best = (x0[:3], pose_rotations(x0[None])[0])
    for step in progress(range(1, L + 1), total=L, desc=f"MUPF {model.name}", quiet=quiet, unit="point"):
        k_bar = max(step - m + 1, 1)
        window = ys[k_bar - 1:step]
        # estimation weights (eq. 4.24): l(y_k)^(m - t + k - 1) on top of the propagated weights
        expo = (m - step + np.arange(k_bar, step + 1) - 1).astype(np.float64)
        z = rng.standard_normal((n, N_X))
        ukf.mupf_step(mode, params.proposal == "sample", t, e, R, P, q_diag, ys[step - 1], window, expo, z, wm, wc, spread, sig2, f.lo, f.step,
                      f.sdf, f.normals, t_bar, e_bar, R_bar, t_hat, e_hat, R_hat, P_new, chol, log_q, log_l, log_l_est)
        # eqs. 4.18-4.19: w_t = w_{t-1} l_window / q
        log_w = _normalised(log_w_prev + log_l - (log_q if params.divide_by_proposal else 0.0))
        if observer is not None:
            observer(step, t_hat, R_hat, log_w)
        if step == L or track_index:
            extra = log_q if params.literal_estimate_weights else 0.0
            log_w_bar = _normalised(log_w + log_l_est - extra)
            # candidates: the particles x_hat (eq. 4.28) and, with map_candidates "both", their UKF means x_bar
            if params.map_candidates == "both":
                tc, ec, Rc = (np.concatenate(p) for p in ((t_hat, t_bar), (e_hat, e_bar), (R_hat, R_bar)))
            else:
                tc, ec, Rc = t_hat, e_hat, R_hat
            scores = np.empty(len(tc))
            ukf.map_scores(mode, tc, ec, Rc, t_hat, e_hat, R_hat, chol, log_w_bar, scores)
            j = int(np.argmax(scores))
            best = (tc[j].copy(), Rc[j].copy())
            if step == L and params.refine:
                best = _refine_candidates(model, ys, best, tc, Rc, np.concatenate([log_w_bar, log_w_bar])
                                          if len(tc) > n else log_w_bar, params)
            if track_index:
                history.append(model.performance_index(_pose_vector(*best), ys))
        ess = 1.0 / np.exp(2 * log_w).sum()
        if step > params.t0 and ess <= params.resample_ess * n:  # resampling after t0 steps (Alg. 2 l. 27-30)
            idx = _systematic_resample(log_w, rng)
            t, e, R, P = t_hat[idx], e_hat[idx], R_hat[idx], P_new[idx]
            log_w_prev = np.full(n, -math.log(n))
        else:
            t, e, R, P = t_hat.copy(), e_hat.copy(), R_hat.copy(), P_new.copy()
            log_w_prev = log_w if step > params.t0 else np.full(n, -math.log(n))
    seconds = time.perf_counter() - start
    pose = _pose_vector(*best)
    max_index = params.max_index if params.max_index is not None else 1.5 * params.noise
    Rp = pose_rotations(pose[None])[0]
    dist = model.exact_distances((ys - pose[:3]) @ Rp)
    index, p90 = float(dist.mean()), float(np.percentile(dist, 90))
    std = pose_std(model, ys, pose[:3], Rp, params.noise)
    return MupfResult(pose=pose, index=index, converged=converged_rule(index, p90, max_index),
                      max_index=max_index, seconds=seconds, window=m, index_history=history, index_p90=p90,
                      pose_std=std, ambiguous=not pinned(std) or degenerate_spread(ys, model.diameter) is not None)


MAX_POSE_STD = (0.01, math.radians(5.0))  # m, rad: a pose the points pin less than this is ambiguous
# points within this fraction of the model's size of one point or of a line leave the turns about it free
DEGENERATE_SPREAD = 1e-3


def converged_rule(index: float, p90: float, max_index: float) -> bool:
    """A pose fits at the noise level: mean distance <= max_index and 90 % of the points within 5/3 of it
    (a wrong basin that fits most points closely still leaves a tail of far ones)."""
    return bool(index <= max_index and p90 <= max_index * 5 / 3)


def pinned(std: np.ndarray) -> bool:
    """The points fix the pose within MAX_POSE_STD along every axis (refine.pose_std); else other poses fit
    them as well (a box touched on four faces slides; a dome touched on its cap turns)."""
    return bool(np.all(std[:3] <= MAX_POSE_STD[0]) and np.all(std[3:] <= MAX_POSE_STD[1]))


def degenerate_spread(points: np.ndarray, size: float) -> str | None:
    """What leaves the pose free when every point lies within DEGENERATE_SPREAD x size (the model's diameter) of one
    point ("one point": every turn about it fits) or of a line ("a line": the turn about it fits, the points
    being on the axis); None otherwise."""
    centred = points - points.mean(0)
    tol = DEGENERATE_SPREAD * size
    far = float(np.linalg.norm(centred, axis=1).max())
    if far <= tol:
        return f"lie within {far:.2g} m of one point: every turn about it fits them as well"
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    off = float(np.linalg.norm(centred - np.outer(centred @ axis, axis), axis=1).max())
    if off <= tol:
        return (f"lie within {off:.2g} m of a line along {np.round(axis, 3).tolist()}: the turn about it fits "
                f"them as well")
    return None


def _distinct(tc: np.ndarray, Rc: np.ndarray, order: np.ndarray, k: int, min_m: float = 0.01,
              min_rad: float = 0.17) -> list[int]:
    """Up to k indices in `order` whose poses differ pairwise by > min_m or > min_rad (greedy)."""
    keep: list[int] = []
    for i in order:
        if len(keep) >= k:
            break
        if keep:
            dt = np.linalg.norm(tc[keep] - tc[i], axis=1)
            cos = (np.einsum("kab,ab->k", Rc[keep], Rc[i]) - 1) / 2
            if np.any((dt <= min_m) & (np.arccos(np.clip(cos, -1, 1)) <= min_rad)):
                continue
        keep.append(int(i))
    return keep


def _principal_flips(model: MeshModel) -> tuple[np.ndarray, np.ndarray]:
    """Half turns about the model's three principal axes through its surface centroid c, as (F (3, 3, 3),
    c - F c (3, 3)): the poses a nearly symmetric object is most often mistaken for."""
    pts = model.sample_surface(2000, np.random.default_rng(0))
    c = pts.mean(0)
    _, axes = np.linalg.eigh(np.cov((pts - c).T))
    F = np.stack([2 * np.outer(a, a) - np.eye(3) for a in axes.T])
    return F, c - F @ c


def _refine_candidates(model: MeshModel, ys, best, tc, Rc, log_w, params: MupfParameters):
    """The MAP estimate and the best-weighted distinct candidates, each refined by Gauss-Newton on the points
    (`refine`); the three best are also tried turned half about the model's principal axes (`flips`) and
    refined; the lowest mean distance wins, then a few exact-mesh steps (README, "Localisation")."""
    f = model.field

    def polish(t, R):
        t, R = np.ascontiguousarray(t), np.ascontiguousarray(R)
        index = np.empty(len(t))
        refine_field(t, R, ys, params.refine_iterations, f.lo, f.step, f.sdf, f.normals, index)
        return t, R, index

    idx = _distinct(tc, Rc, np.argsort(-log_w, kind="stable"), params.refine - 1)
    t, R, index = polish(np.concatenate([best[0][None], tc[idx]]), np.concatenate([best[1][None], Rc[idx]]))
    if params.flips:
        top = _distinct(t, R, np.argsort(index, kind="stable"), params.flips)
        F, shift = _principal_flips(model)
        Rf = np.einsum("kab,fbc->kfac", R[top], F).reshape(-1, 3, 3)
        tf = (t[top][:, None] + np.einsum("kab,fb->kfa", R[top], shift)).reshape(-1, 3)
        t2, R2, index2 = polish(tf, Rf)
        t, R, index = np.concatenate([t, t2]), np.concatenate([R, R2]), np.concatenate([index, index2])
    j = int(np.argmin(index))
    tj, Rj, _ = refine_exact(model, ys, t[j].copy(), R[j].copy())
    return tj, Rj


def _pose_vector(t: np.ndarray, R: np.ndarray) -> np.ndarray:
    return np.concatenate([t, matrix_pose(np.block([[R, t[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]))[3:]])


def _normalised(log_w: np.ndarray) -> np.ndarray:
    log_w = np.where(np.isfinite(log_w), log_w, -np.inf)
    peak = log_w.max()
    if not np.isfinite(peak):
        return np.full(len(log_w), -math.log(len(log_w)))
    return log_w - (peak + math.log(np.exp(log_w - peak).sum()))


def parameters_json(params: MupfParameters) -> dict:
    """The parameters as plain JSON values."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(params).items()}
