"""`localize_points`: the driver of `kinfu localize` — MUPF for one model, or recognition over several
(Alg. 3: the model with the lowest I_L) — and its JSON document (pose.json)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.localization.mesh_model import MeshModel
from kinfu_cli.localization.mupf import MupfParameters, MupfResult, check_points, degenerate_spread, \
    estimated_seconds, localize_mupf, parameters_json


def pose_json(result: MupfResult) -> dict | None:
    """The estimate as 4x4, position + quaternion (x, y, z, w) and the filter's Euler angles — only when it
    converged (`mupf.converged_rule`): a non-converged run reports no pose."""
    if not result.converged:
        return None
    T = result.matrix
    return {"matrix": T.tolist(), "position": T[:3, 3].tolist(),
            "quaternion_xyzw": Rotation.from_matrix(T[:3, :3]).as_quat().tolist(),
            "euler_zyx_rad": result.pose[3:6].tolist(), "frame": "model to world (points' frame)"}


def _model_json(model: MeshModel, result: MupfResult) -> dict:
    status = "not_converged" if not result.converged else "ambiguous" if result.ambiguous else "converged"
    return {"model": model.name, "status": status,
            "index_m": result.index, "index_p90_m": result.index_p90, "max_index_m": result.max_index,
            "pose_std": None if result.pose_std is None else [float(v) for v in result.pose_std],
            "seconds": result.seconds,
            "window": result.window, "pose": pose_json(result)}


@dataclass
class LocalizationResult:
    """Per-model MUPF results in the models' order and the recognised one (lowest I_L)."""

    models: list[MeshModel]
    results: list[MupfResult]
    params: MupfParameters
    n_points: int
    prior: list[float]
    warnings: list[str] = field(default_factory=list)

    @property
    def chosen(self) -> int:
        return int(np.argmin([r.index for r in self.results]))

    def to_json(self) -> dict:
        best = self.chosen
        doc = {**_model_json(self.models[best], self.results[best]), "points": self.n_points,
               "prior_mean": self.prior, "parameters": parameters_json(self.params), "warnings": list(self.warnings)}
        if len(self.models) > 1:
            doc["recognition"] = {"chosen": self.models[best].name, "rule": "lowest I_L (thesis Alg. 3)",
                                  "models": [_model_json(m, r) for m, r in zip(self.models, self.results)]}
        return doc


# points the filter runs on at most: thesis ch. 5 localises objects from 100 points of the filtered cloud
MAX_POINTS = 100
# longest filtering a run may be estimated to take (`mupf.estimated_seconds`, measured on this machine, summed over
# the models): 10 minutes. The default 700 particles over 100 points take under 1 s a model (estimated 2 s), 700
# over 5000 points (max_points 0 on a fused segment) ~9 min, over 10000 ~34 min; 50,000 particles ~4 min on the MAP
MAX_SECONDS = 600.0


def check_run_time(params: MupfParameters, n_points: int, n_models: int = 1, n_given: int | None = None) -> float:
    """The estimated seconds of filtering n_points for n_models; ConfigError naming the particles, the points
    (max_points: n_given were given) and the window when it is over MAX_SECONDS, before any filtering."""
    seconds = n_models * estimated_seconds(params, n_points)
    if seconds <= MAX_SECONDS:
        return seconds
    window = params.window if params.window is not None else f"{max(1, math.ceil(n_points / 2))} (half the points)"
    points = f"{n_points} points" + (f" (of {n_given})" if n_given is not None and n_given != n_points else "")
    models = f" x {n_models} models" if n_models > 1 else ""
    raise ConfigError(f"{params.particles} particles over {points}, window {window}{models} would take about "
                      f"{_duration(seconds)} of filtering (time grows with particles x points x window, and with "
                      f"particles^2); expected at most {_duration(MAX_SECONDS)}: use fewer particles (the thesis "
                      f"uses 700-1200) or fewer points", parameter="particles/max_points/window")


def _duration(seconds: float) -> str:
    return f"{seconds / 3600:.1f} h" if seconds >= 5400 else f"{seconds / 60:.0f} min"


def localize_points(models: list[MeshModel], points: np.ndarray, params: MupfParameters = MupfParameters(), *,
                    prior: str | np.ndarray = "centroid", seed: int | None = 0, quiet: bool = True,
                    max_points: int = MAX_POINTS) -> LocalizationResult:
    """MUPF for each model on the same points. prior "centroid" puts the prior mean's position at the points'
    centroid minus the model's (the thesis' x0 = 0 assumes points around the model origin); "zero" is the
    thesis' null vector; or a 6-vector. max_points: more points than this (a fused segment has thousands, and
    the filter takes them one at a time) are thinned to this many, in their order, seeded (0: all)."""
    if not models:
        raise ConfigError("expected at least one model", parameter="models")
    pts = check_points(points)
    check_number(max_points, "max_points", 0, integer=True)
    if seed is not None:
        check_number(seed, "seed", 0, 2 ** 63 - 1, integer=True)  # numpy refuses negative seeds with a bare ValueError
    thinned = 0 < max_points < len(pts)
    n_given = len(pts)
    if thinned:
        keep = np.sort(np.random.default_rng(seed).choice(len(pts), max_points, replace=False))
        pts = pts[keep]
    params.check()
    if params.window is not None and params.window > len(pts):
        raise ConfigError(f"window {params.window} exceeds the {len(pts)} points", parameter="window")
    check_run_time(params, len(pts), len(models), n_given)
    results, priors = [], []
    for model in models:
        model.build_field()
        if isinstance(prior, str):
            if prior not in ("centroid", "zero"):
                raise ConfigError(f"expected 'centroid', 'zero' or 6 numbers, got {prior!r}", parameter="prior")
            x0 = np.zeros(6)
            if prior == "centroid":
                x0[:3] = pts.mean(0) - model.vertices.mean(0)
        else:
            x0 = np.asarray(prior, dtype=float)
            if x0.shape != (6,) or not np.all(np.isfinite(x0)):
                raise ConfigError("expected 6 finite numbers x,y,z,phi,theta,psi", parameter="prior")
        priors.append(x0.tolist())
        results.append(localize_mupf(model, pts, params, x0=x0, seed=seed, quiet=quiet))
    res = LocalizationResult(models, results, params, len(pts), priors[0])
    if not results[res.chosen].converged:
        r = results[res.chosen]
        res.warnings.append(f"MUPF did not converge: the points do not fit at the noise level (I_L {r.index:.4f} m, "
                            f"90th percentile {r.index_p90:.4f} m; limits {r.max_index:.4f} / "
                            f"{r.max_index * 5 / 3:.4f} m; no pose reported)")
    elif results[res.chosen].ambiguous and (free := degenerate_spread(pts, models[res.chosen].diameter)):
        res.warnings.append(f"the points do not pin the pose: they {free} (status ambiguous)")
    elif results[res.chosen].ambiguous:
        res.warnings.append(f"the points do not pin the pose: standard deviations "
                            f"{np.round(results[res.chosen].pose_std, 4).tolist()} (m, rad) exceed 0.01 m / 5 deg "
                            f"somewhere; other poses fit as well (status ambiguous)")
    if thinned:
        res.warnings.append(f"used {len(pts)} of the {n_given} points, spread over them in their order "
                            f"(max_points; the thesis runs the filter on 100 points of a cloud)")
    if len(pts) < 10:
        res.warnings.append(f"only {len(pts)} points: the pose may be ambiguous (the thesis uses 15-62)")
    spread = float(np.linalg.norm(pts - pts.mean(0), axis=1).max())
    if spread > 2 * max(m.diameter for m in models):
        res.warnings.append(f"the points spread {spread:.2f} m, over twice the model size: are they one object?")
    return res
