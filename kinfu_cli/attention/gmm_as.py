"""GMM-AS: Gaussian Mixture Model Activity Saliency (Monica et al. RAS 2016, Alg. 3, eqs. 12-13).

Algorithm (paper): fit a GMM on the 4-D samples (x, y, z, t) by EM, initialised by splitting the time
span into GC equal segments (mean and covariance of each); GC = 1, 2, ... until BIC exceeds its
minimum by BICTh (first local minimum); sort the Gaussians by mean time; give each a saliency
s = σ1σ2σ3 / (σ1+σ2+σ3) · π · c* (σi = sqrt|λi| of the covariance "marginalised over Cartesian
coordinates", π the weight, c* the count); the Gaussian g (first and last skipped) is a POI when
s_g > POITh × the mean saliency of its Λ neighbours on each side.

Reading chosen here, and why (measured on the public subset only: users 1 and 4, 130 tasks)
-------------------------------------------------------------------------------------------
1. Time scaling of the 4th coordinate. EM, the time-segment initialisation and BIC are all
   equivariant under scaling one coordinate: multiplying t by any constant gives the same mixture
   (the log-likelihood shifts by N·log(scale) for every K alike). The time unit (seconds, samples,
   metres per mean speed) therefore matters ONLY through the covariance regularisation. We use
   normalised time τ = (t − t0) / duration (`time_scale="duration"`) and resample each task to a
   fixed `resample` = 300 samples (≈ 3 s at the tracker's 100 Hz, the median task length), so the
   mixture depends on the path and on the relative time spent along it, not on how fast the task
   was performed or on the tracker rate (Table 3's speed multipliers become a no-op by design).
   `time_scale` may be a number (units per second; 1.0 = seconds) and `resample=0` keeps the raw
   samples, for the literal reading.
2. Covariance regularisation. Without a floor (sklearn's 1e-6) BIC keeps falling up to any Kmax on
   these sub-millimetre tracks (smooth curves are modelled ever better by more, thinner Gaussians),
   so the "first local minimum" is often never reached (K runs to Kmax). A variance floor added to
   the diagonal at every M-step — σ = 5 mm in space (tracker jitter + wrist tremor) and 0.03 of the
   task duration in time — reaches a first BIC minimum well below Kmax (7-13 on the pick-and-place
   tasks; the paper's examples have 6 and 7). When the track is
   noisier than the floor (estimated from second differences, robust MAD), the path is first
   mean-filtered over ≈ (noise / floor)² samples (at most a tenth of the task) and the floor is raised
   to the remaining noise (`noise_floor=1.0`; 0 disables both). This is what keeps recall at 2.5 and
   5 cm of added noise (Table 4).
   The time floor was 0.1 × duration until held-out users 2+3 showed pick-and-place recall 93.3 %.
   Every missed pick-and-place action on users 1+4 (recorded, and with pauses played 4× faster:
   evaluation/poi_loo.py `quicken_pauses`) is the FIRST of the two actions, with the hand within 5 cm
   for only 0.18-0.30 s, 0.7-1.2 s before the second: under a time std ≥ 0.1 × duration (0.2-0.33 s)
   the short grasp is spread over two Gaussians of middling saliency beside the very salient second
   action, which lifts their neighbours' mean above them. Resampling is not the cause (300 samples put
   6-11 ms between samples, 20-50 per pause; `resample=0` gives the same fits). Leave-one-user-out
   (reg_time 0.02-0.15, score = min precision / recall over groups, recorded + quick-grasp): user 1 is
   at its ceiling for every value, user 4 is best at 0.02-0.03 (97.5; 0.1: 92.5); of the two values
   best on both we keep 0.03, the larger (without merging, 0.02 lost user 1 a point: 93.5). Same speed / noise sweeps with 0.03: recall 96-97 % at 0.25x-4x, and
   ≥ 90 % in every group at 5 cm of noise.
3. "Eigenvalues of the covariance marginalised over Cartesian coordinates". Taken literally (σ =
   sqrt of the eigenvalues of the 3×3 spatial block, eq. 13) the still hand of an action makes a
   SMALL Gaussian and the long transport Gaussians score higher. Measured on users 1+4 (recall,
   pick-and-place / placements): the paper read literally (`GmmActivitySaliency.LITERAL`: raw samples,
   t in s, 1 mm floor, eq. 13, POITh 2.5, Σ/2Λ) 0 % / 0 % (23 POIs, all false); eq. 13 on the
   spatial block with everything else as below 7 % / 11 %. The reading that reproduces the paper
   is that the matrix the eigenvalues come from is the Gaussian's PRECISION (inverse covariance,
   what an EM implementation keeps for the E-step), restricted to its x, y, z block
   (`saliency="precision"`): then σ_i = 1/std along the principal axes of the spatial part
   conditioned on t, and s = σ1σ2σ3/(σ1+σ2+σ3)·π·c* = π·c* / (s1s2 + s1s3 + s2s3) in terms of the
   standard deviations s_i — large for compact, heavy Gaussians (the hand dwelling at an action),
   small for long, narrow transport Gaussians: exactly the paper's description of which Gaussians
   are salient, and the absolute value in σ = sqrt|λ| is natural there. Same fits, recall:
   precision block 98 % / 93.75 % (placements at their ceiling, below); weight only (π·c*)
   76 % / 87.5 %; covariance conditioned on t 6 % / 7.5 %. `saliency` keeps
   "literal", "weight" and "conditional" (covariance conditioned on t) for comparison.
4. Thresholds. Tables 5 and 6 of the paper (thesis 2.5/2.6) print a "threshold" that equals
   1.5 × the mean of the AVAILABLE neighbours within Λ = 2 in all nine rows (e.g. Table 5 row 2:
   (s1 + s3 + s4)/3 × 1.5 = 0.040424), not (1/2Λ)·Σ × 2.5. So the worked examples used POITh = 1.5 and
   averaged only existing neighbours; that is our default (`poi_threshold=1.5`,
   `threshold_mode="available"`). `threshold_mode="literal"` divides by 2Λ as printed in Alg. 3;
   POITh = 2.5 (Table 2's caption) gives the same precision and 2 points less pick-and-place
   recall here (96 %), and loses more under noise (86 % recall at 2.5 cm vs 95.6 %).

Ceiling: placements cannot exceed 93.75 % recall for ANY detector on users 1+4, because 5 of the 80
labelled changes (spray-can tasks) lie 0.21-0.27 m from every sample of their trajectory, beyond the
0.20 m match radius; one pick-and-place label (user1_spray_can5) is 1.0 m from its trajectory.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.attention.em import Mixture, fit_em
from kinfu_cli.attention.zvc import mean_filter
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, TrajectoryError
from kinfu_cli.core.pois import DEFAULT_RADIUS, Gaussian4, Poi
from kinfu_cli.io.trajectory import Trajectory

SALIENCY_MODES = ("precision", "literal", "weight", "conditional")
THRESHOLD_MODES = ("available", "literal")
SELECTION_MODES = ("first-minimum", "best")
#: A sample gap longer than this many median periods is a tracking dropout, not dwell time.
GAP_FACTOR = 5.0
# the fewest Gaussians a resampled task must have samples for (resample >= this x min_samples_per_component)
RESAMPLE_GAUSSIANS = 4


# the fewest Gaussians a fit needs for a POI: one with a neighbour on each side (the first and last are skipped)
MIN_POI_GAUSSIANS = 3
#: the numeric time_scale range (units per second): megaseconds to microseconds; beyond it the variances
#: overflow (1e-300 and inf printed numpy warnings)
MIN_TIME_SCALE, MAX_TIME_SCALE = 1e-6, 1e6

class GmmActivitySaliency:
    """GMM-AS POI detector (sklearn-style: parameters here, work in `fit`, results in `*_`).

    Parameters (paper names in capitals):
      poi_threshold    POITh  multiplier on the neighbours' mean saliency (default 1.5, Tables 5-6;
                              the paper's Table 2 caption says 2.5).
      neighbours       Λ      neighbours on each side averaged for the threshold (2).
      bic_threshold    BICTh  stop when BIC > min BIC + BICTh (0: first local minimum).
      max_components   Kmax   upper bound on GC (also limited to N / min_samples_per_component).
      selection               "first-minimum" (the paper) or "best" (min BIC over 1..Kmax).
      time_scale              "duration" (t normalised to [0, 1]) or units per second (1.0 = seconds).
      reg_space        m      σ floor added (as σ²) to the spatial covariance diagonal (0.005).
      reg_time                σ floor on the time axis in the units of `time_scale` (0.03; was 0.1, see §2).
      saliency                "precision" (eq. 13 on the x, y, z block of the inverse covariance; default),
                              "literal" (eq. 13 on the spatial covariance), "weight" (π·c*), "conditional".
      resample                resample each task to this many samples, uniformly in time (300; 0 = raw).
      noise_floor             raise the spatial floor to this × the estimated sensor noise, mean-filtering
                              the path first when it is noisier than the floor (1.0; 0 = off).
      threshold_mode          "available" (mean of existing neighbours) or "literal" (Σ / 2Λ).
      merge_distance   m      consecutive POI Gaussians whose means are closer than this are one POI (weight-
                              averaged position and time; 0.05; 0 = one POI per Gaussian, the paper): with
                              the 0.03 × duration time floor a pause longer than ~0.2 of the task (synthetic
                              hands dwell 1 s) splits over two Gaussians at the same place.
      radius           WS_r   region radius written with each POI (0.2 m).
      max_iter, tol           EM limits (tol on the mean log-likelihood per sample).
      min_samples_per_component  GC ≤ N / this (8).

    After `fit(traj)`: `pois_`, `gaussians_` (Gaussian4 in (x, y, z, t seconds), sorted by time),
    `saliency_` (K,), `thresholds_` (K,; NaN for the first and last), `bic_` {K: BIC},
    `n_components_`, `mixture_` (the raw Mixture in the scaled coordinates), `noise_` (estimated
    sensor noise, m), `smoothing_half_width_` (mean filter applied, samples; 0 = none).
    `GmmActivitySaliency.LITERAL` holds the parameters of the paper read literally, for comparison.
    """

    algorithm = "gmm-as"

    def __init__(self, poi_threshold: float = 1.5, neighbours: int = 2, bic_threshold: float = 0.0,
                 max_components: int = 15, selection: str = "first-minimum", time_scale: str | float = "duration",
                 reg_space: float = 0.005, reg_time: float = 0.03, saliency: str = "precision",
                 threshold_mode: str = "available", radius: float = DEFAULT_RADIUS, max_iter: int = 100,
                 tol: float = 1e-4, min_samples_per_component: int = 8, resample: int = 300,
                 noise_floor: float = 1.0, merge_distance: float = 0.05) -> None:
        self.poi_threshold = poi_threshold
        self.neighbours = neighbours
        self.bic_threshold = bic_threshold
        self.max_components = max_components
        self.selection = selection
        self.time_scale = time_scale
        self.reg_space = reg_space
        self.reg_time = reg_time
        self.saliency = saliency
        self.threshold_mode = threshold_mode
        self.radius = radius
        self.max_iter = max_iter
        self.tol = tol
        self.min_samples_per_component = min_samples_per_component
        self.resample = resample
        self.noise_floor = noise_floor
        self.merge_distance = merge_distance

    #: The paper read literally: raw samples, t in seconds, sklearn's 1e-6 variance floor (σ = 1 mm),
    #: eq. 13 on the spatial covariance, POITh 2.5 and Σ/2Λ as printed in Alg. 3.
    LITERAL = {"saliency": "literal", "resample": 0, "time_scale": 1.0, "reg_space": 1e-3, "reg_time": 1e-3,
               "noise_floor": 0.0, "poi_threshold": 2.5, "threshold_mode": "literal", "merge_distance": 0.0}

    def get_params(self) -> dict:
        return {k: getattr(self, k) for k in (
            "poi_threshold", "neighbours", "bic_threshold", "max_components", "selection", "time_scale",
            "reg_space", "reg_time", "saliency", "threshold_mode", "radius", "max_iter", "tol",
            "min_samples_per_component", "resample", "noise_floor", "merge_distance")}

    def check_params(self) -> None:
        """Raise ConfigError naming the first bad parameter (called by `fit`; callers check before any work)."""
        if self.saliency not in SALIENCY_MODES:
            raise ConfigError(f"expected one of {', '.join(SALIENCY_MODES)}, got {self.saliency!r}",
                              parameter="saliency")
        if self.threshold_mode not in THRESHOLD_MODES:
            raise ConfigError(f"expected one of {', '.join(THRESHOLD_MODES)}, got {self.threshold_mode!r}",
                              parameter="threshold_mode")
        if self.selection not in SELECTION_MODES:
            raise ConfigError(f"expected one of {', '.join(SELECTION_MODES)}, got {self.selection!r}",
                              parameter="selection")
        if self.time_scale != "duration":
            try:  # finite and in range: inf made NaN times (a numpy warning, then an empty fit)
                ok = MIN_TIME_SCALE <= float(self.time_scale) <= MAX_TIME_SCALE
            except (TypeError, ValueError, OverflowError):
                ok = False
            if not ok:
                raise ConfigError(f"expected 'duration' or a number from {MIN_TIME_SCALE:g} to {MAX_TIME_SCALE:g} "
                                  f"(units per second), got {self.time_scale!r}", parameter="time_scale")
        # finite and of a sensible size: NaN slips through comparisons, 1e300 overflows a variance
        check_number(self.neighbours, "neighbours", 1, 1000, integer=True)
        check_number(self.max_components, "max_components", 1, 1000, integer=True)
        if self.max_components < MIN_POI_GAUSSIANS:
            raise ConfigError(f"expected at least {MIN_POI_GAUSSIANS}: a POI is a Gaussian between two others (the "
                              f"first and last of a fit never are), so a fit of {self.max_components} can never give "
                              f"one", parameter="max_components")
        check_number(self.poi_threshold, "poi_threshold", 0, 1e6, low_open=True)
        check_number(self.radius, "radius", 0, 100, low_open=True, unit="m")
        check_number(self.bic_threshold, "bic_threshold", -1e12, 1e12)
        check_number(self.reg_space, "reg_space", 0, 100, unit="m")
        check_number(self.reg_time, "reg_time", 0, 1e6)
        check_number(self.noise_floor, "noise_floor", 0, 1e3)
        check_number(self.merge_distance, "merge_distance", 0, 100, unit="m")
        check_number(self.resample, "resample", 0, 1e6, integer=True)
        check_number(self.max_iter, "max_iter", 1, 1e6, integer=True)
        check_number(self.tol, "tol", 0, 1, low_open=True)
        check_number(self.min_samples_per_component, "min_samples_per_component", 1, 1e6, integer=True)
        # a resampled task must hold a few Gaussians' samples: 1 ran as raw samples, 2-5 fitted nothing (0 POIs)
        fewest = RESAMPLE_GAUSSIANS * int(self.min_samples_per_component)
        if 0 < int(self.resample) < fewest:
            raise ConfigError(f"expected 0 (raw samples) or at least {fewest} samples ({RESAMPLE_GAUSSIANS} Gaussians of "
                              f"min_samples_per_component), got {self.resample}", parameter="resample")

    # --- steps ---------------------------------------------------------------------------------
    def _samples(self, traj: Trajectory, smooth: int = 0) -> tuple[np.ndarray, float, tuple[np.ndarray, np.ndarray]]:
        """(x, y, z, scaled t) samples, the time scale, and (model clock, trajectory clock), both from 0."""
        t = traj.t - traj.t[0]
        pos = traj.positions
        dt = np.diff(t)
        if len(dt) and dt.max() > GAP_FACTOR * np.median(dt):
            # tracking gaps carry no dwell information: shorten each to GAP_FACTOR sample periods
            t = np.r_[0.0, np.cumsum(np.minimum(dt, GAP_FACTOR * np.median(dt)))]
        clock = (t, traj.t - traj.t[0])
        if smooth > 0:
            pos = mean_filter(pos, smooth)
        if self.resample:
            tt = np.linspace(0.0, t[-1], int(self.resample))
            pos = np.column_stack([np.interp(tt, t, pos[:, i]) for i in range(3)])
            t = tt
        if self.time_scale == "duration":
            scale = 1.0 / max(float(t[-1]), 1e-12)
        else:
            scale = float(self.time_scale)
        return np.column_stack([pos, t * scale]), scale, clock

    @staticmethod
    def estimate_noise(positions: np.ndarray) -> float:
        """White-noise std (m) from second differences: robust (MAD) and blind to smooth motion."""
        if len(positions) < 5:
            return 0.0
        dd = positions[2:] - 2 * positions[1:-1] + positions[:-2]
        mad = np.median(np.abs(dd - np.median(dd, axis=0)), axis=0) * 1.4826
        return float(np.sqrt(np.mean(mad ** 2) / 6.0))

    def _select(self, x: np.ndarray, reg_space: float) -> tuple[Mixture, dict]:
        n = x.shape[0]
        reg = np.array([reg_space ** 2] * 3 + [self.reg_time ** 2], dtype=np.float64)
        reg = np.maximum(reg, 1e-12)
        kmax = max(1, min(int(self.max_components), n // int(self.min_samples_per_component)))
        bics: dict[int, float] = {}
        best: Mixture | None = None
        min_bic = np.inf
        for k in range(1, kmax + 1):
            m = fit_em(x, k, reg, max_iter=int(self.max_iter), tol=float(self.tol))
            b = m.bic(n)
            bics[k] = b
            if b < min_bic:
                min_bic, best = b, m
            elif self.selection == "first-minimum" and b > min_bic + self.bic_threshold:
                break
        if best is None:  # every fit's BIC was NaN: the samples defeat the arithmetic (validated data should not)
            raise TrajectoryError(f"GMM-AS: no mixture of 1..{kmax} components fits the {n} samples with a finite "
                                  f"likelihood (BIC {', '.join(f'{b:g}' for b in bics.values())})")
        return best, bics

    def _saliency(self, weights: np.ndarray, covs: np.ndarray) -> np.ndarray:
        k = len(weights)
        if self.saliency == "weight":
            return weights * k
        spatial = covs[:, :3, :3]
        if self.saliency == "precision":
            spatial = np.linalg.inv(covs)[:, :3, :3]
        elif self.saliency == "conditional":
            spatial = spatial - np.einsum("ki,kj->kij", covs[:, :3, 3], covs[:, :3, 3]) / covs[:, 3, 3][:, None, None]
        sig = np.sqrt(np.abs(np.linalg.eigvalsh(spatial)))
        return sig.prod(axis=1) / np.maximum(sig.sum(axis=1), 1e-300) * weights * k

    def _thresholds(self, s: np.ndarray) -> np.ndarray:
        k = len(s)
        lam = int(self.neighbours)
        th = np.full(k, np.nan)
        for g in range(1, k - 1):
            idx = [j for j in range(g - lam, g + lam + 1) if j != g and 0 <= j < k]
            base = s[idx].mean() if self.threshold_mode == "available" else s[idx].sum() / (2 * lam)
            th[g] = self.poi_threshold * base
        return th

    def fit(self, traj: Trajectory) -> "GmmActivitySaliency":
        self.check_params()
        traj.validate(min_samples=2)
        reg_space = float(self.reg_space)
        self.noise_ = noise = self.estimate_noise(traj.positions)
        half = 0
        if self.noise_floor and reg_space > 0 and noise > reg_space:
            # white noise above the floor: average ~(noise/floor)^2 samples, at most a tenth of the task
            width = min((noise / reg_space) ** 2, len(traj) / 10.0)
            half = int(max(0, np.ceil((width - 1) / 2)))
            noise = noise / np.sqrt(2 * half + 1)
        self.smoothing_half_width_ = half
        x, scale, (clock, real) = self._samples(traj, half)
        if self.noise_floor:
            reg_space = max(reg_space, float(self.noise_floor) * noise)
        mix, bics = self._select(x, reg_space)
        order = np.argsort(mix.means[:, 3])
        w, mu, cov = mix.weights[order], mix.means[order], mix.covariances[order]
        s = self._saliency(w, cov)
        th = self._thresholds(s)
        # Gaussians back in (x, y, z, t seconds) on the trajectory's clock
        to_sec = np.array([1.0, 1.0, 1.0, 1.0 / scale])
        gaussians = []
        for j in range(len(w)):
            mean = mu[j] * to_sec
            mean[3] = traj.t[0] + float(np.interp(mean[3], clock, real))  # undo gap shortening
            gaussians.append(Gaussian4(mean=mean, covariance=cov[j] * np.outer(to_sec, to_sec), weight=float(w[j])))
        runs: list[list[int]] = []
        for g in range(1, len(w) - 1):
            if s[g] > th[g]:
                if runs and runs[-1][-1] == g - 1 and np.linalg.norm(mu[g, :3] - mu[g - 1, :3]) < self.merge_distance:
                    runs[-1].append(g)  # one long pause split over consecutive Gaussians: one action
                else:
                    runs.append([g])
        pois = []
        for run in runs:
            g = max(run, key=lambda j: s[j])  # the most salient Gaussian of the pause speaks for it
            wr = w[run] / w[run].sum()
            pois.append(Poi(id=len(pois), position=wr @ mu[run, :3],
                            time=float(wr @ np.array([gaussians[j].mean[3] for j in run])),
                            saliency=float(s[g]), radius=float(self.radius), gaussian=gaussians[g],
                            extra={"component": int(g), "threshold": float(th[g]),
                                   **({"merged_components": [int(j) for j in run]} if len(run) > 1 else {})}))
        self.mixture_ = mix
        self.gaussians_ = gaussians
        self.saliency_ = s
        self.thresholds_ = th
        self.bic_ = bics
        self.n_components_ = len(w)
        self.pois_ = pois
        return self
