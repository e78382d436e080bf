"""`kinfu eval localize`: the thesis' Table 4.2 protocol (MUPF) with both baselines in the same run on the
same measurements, and the ch. 5 recognition experiment on six near-identical generated blocks."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.progress import progress
from kinfu_cli.core.memory import USABLE_FRACTION, available_bytes
from kinfu_cli.localization import shapes
from kinfu_cli.localization.localize import check_run_time
from kinfu_cli.localization.baselines import localize_ransac_icp, localize_scaling_series
from kinfu_cli.localization.mesh_model import pose_matrix
from kinfu_cli.localization.mupf import MupfParameters, localize_mupf
from kinfu_cli.localization.protocol import add_s, make_trial, pose_errors

METHODS = ("mupf", "scaling_series", "ransac_icp")
# thesis Table 4.2 (MUPF) and Table 4.4 (Scaling Series): std error deg, m; I_L m; time s; successes of 50
THESIS = {
    "mupf": {"box": (0.30, 0.0036, 0.0025, 1.61, 50), "tetrahedron": (17.1, 0.0061, 0.0021, 3.63, 50),
             "cleaner": (0.78, 0.0027, 0.0025, 7.32, 50), "robot": (19.6, 0.0072, 0.0021, 3.95, 50),
             "helmet": (0.06, 0.0023, 0.0017, 4.82, 50)},
    "scaling_series": {"box": (None, None, 0.001, 3.47, 45), "tetrahedron": (None, None, 0.001, 0.05, 50),
                       "cleaner": (None, None, 0.006, 0.03, 42), "robot": (None, None, 0.003, 0.02, 43),
                       "helmet": (None, None, 0.005, 0.04, 32)},
}
SUCCESS_ADD_S = 0.01  # m: mean surface-to-surface distance of a correct pose (symmetric shapes)
SUCCESS_DEG, SUCCESS_M = 30.0, 0.02  # non-symmetric shapes: also within these of the true pose
# bytes a recognition trial holds per point: 170 generating it, 280 in the filter (tracemalloc peaks, 200 000
# points), open3d's and numba's buffers besides
BYTES_PER_RECOGNITION_POINT = 1024


def _summary(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["success"]]
    rot = np.array([r["rotation_error_deg"] for r in rows])
    tra = np.array([r["translation_error_m"] for r in rows])
    sec = np.array([r["seconds"] for r in rows])
    return {"trials": len(rows), "successes": len(ok),
            "rms_rotation_error_deg": float(np.sqrt(np.mean(rot ** 2))),
            "rms_translation_error_m": float(np.sqrt(np.mean(tra ** 2))),
            "median_rotation_error_deg": float(np.median(rot)), "median_translation_error_m": float(np.median(tra)),
            "mean_index_m": float(np.mean([r["index_m"] for r in rows])),
            "mean_add_s_m": float(np.mean([r["add_s_m"] for r in rows])),
            "mean_seconds": float(sec.mean()), "max_seconds": float(sec.max()),
            "mean_cpu_seconds": float(np.mean([r["cpu_seconds"] for r in rows])),
            "max_cpu_seconds": float(np.max([r["cpu_seconds"] for r in rows])),
            "converged": int(sum(r.get("converged", True) for r in rows)),
            "converged_but_failed": int(sum(r.get("converged", False) and not r["success"] for r in rows)),
            "ambiguous": int(sum(r.get("ambiguous", False) for r in rows)),
            "unambiguous_converged_but_failed": int(sum(r.get("converged", False) and not r.get("ambiguous", True)
                                                        and not r["success"] for r in rows))}


def _row(model, samples, name, trial, pose, index, seconds, **extra) -> dict:
    E = pose_matrix(pose)
    rot, tra = pose_errors(E, trial.matrix)
    adds = add_s(model, E, trial.matrix, samples)
    ok = adds <= SUCCESS_ADD_S and (name in shapes.SYMMETRIC or (rot <= SUCCESS_DEG and tra <= SUCCESS_M))
    return {"rotation_error_deg": rot, "translation_error_m": tra, "add_s_m": adds, "index_m": index,
            "seconds": seconds, "success": bool(ok), **extra}


def evaluate_localization(names=tuple(shapes.SIMULATION_SHAPES), *, trials: int = 50, noise: float = 0.002,
                          params: MupfParameters = MupfParameters(), methods=METHODS, seed: int = 0,
                          quiet: bool = True) -> dict:
    """Table 4.2 over `names`: per shape `trials` true poses and measurement sets (L, m of Table 4.3), each
    localised by every method in `methods`; per-trial rows, per-shape summaries and the thesis' numbers."""
    check_number(trials, "trials", 1, integer=True)
    check_number(noise, "noise", 0, unit="m")
    check_number(seed, "seed", 0, 2 ** 63 - 1, integer=True)  # numpy refuses negative seeds with a bare ValueError
    unknown = [n for n in names if n not in shapes.SIMULATION_SHAPES]
    if unknown:
        raise ConfigError(f"unknown shape(s) {', '.join(unknown)} (expected {', '.join(shapes.SIMULATION_SHAPES)})",
                          parameter="shapes")
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ConfigError(f"unknown method(s) {', '.join(bad)} (expected {', '.join(METHODS)})", parameter="methods")
    if "mupf" in methods:  # localize's upfront bound on one filter run, before the first trial
        for name in names:
            L, m = shapes.TABLE_4_3[name]
            _check_time(replace(params, window=m), L, 1, "particles")
    rng = np.random.default_rng(seed)
    doc: dict = {"protocol": {"trials": trials, "noise_m": noise, "offset_m": [0.05, 0.1], "rotation_deg": [45, 90],
                              "success": f"ADD-S <= {SUCCESS_ADD_S} m, and for non-symmetric shapes rotation error "
                                         f"<= {SUCCESS_DEG} deg and translation error <= {SUCCESS_M} m",
                              "symmetric": sorted(shapes.SYMMETRIC), "table_4_3": shapes.TABLE_4_3},
                 "parameters": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(params).items()},
                 "shapes": {}, "thesis": THESIS}
    jobs = [(n, k) for n in names for k in range(trials)]
    models = {}
    per: dict[str, dict[str, list]] = {n: {m: [] for m in methods} for n in names}
    for name, k in progress(jobs, total=len(jobs), desc="eval localize", quiet=quiet, unit="trial"):
        if name not in models:
            models[name] = shapes.SIMULATION_SHAPES[name]()
            models[name].build_field()
        model = models[name]
        samples = model.sample_surface(3000, np.random.default_rng(99))
        L, m = shapes.TABLE_4_3[name]
        trial = make_trial(model, L, noise, rng)
        s = int(rng.integers(2 ** 31))
        if "mupf" in methods:
            c = time.process_time()
            r = localize_mupf(model, trial.points, replace(params, window=m), seed=s)
            per[name]["mupf"].append(_row(model, samples, name, trial, r.pose, r.index, r.seconds,
                                          converged=r.converged, ambiguous=r.ambiguous,
                                          cpu_seconds=time.process_time() - c))
        if "scaling_series" in methods:
            c = time.process_time()
            b = localize_scaling_series(model, trial.points, seed=s)
            per[name]["scaling_series"].append(_row(model, samples, name, trial, b.pose, b.index, b.seconds,
                                                    particles_evaluated=b.evaluated, capped=b.capped,
                                                    cpu_seconds=time.process_time() - c))
        if "ransac_icp" in methods:
            c = time.process_time()
            b = localize_ransac_icp(model, trial.points, seed=s)
            per[name]["ransac_icp"].append(_row(model, samples, name, trial, b.pose, b.index, b.seconds,
                                                cpu_seconds=time.process_time() - c))
    for name in names:
        doc["shapes"][name] = {m: {"summary": _summary(rows), "trials": rows} for m, rows in per[name].items()}
    return doc


def check_recognition(trials: int, n_points: int, params: MupfParameters = MupfParameters()) -> None:
    """ConfigError unless `evaluate_recognition` can run these (a command checks before its long first part):
    trials >= 0, 3 <= n_points, their memory within what is available and a trial's filtering (MUPF on every
    block) within localize's bound (check_run_time)."""
    check_number(trials, "recognition_trials", 0, integer=True)
    check_number(n_points, "recognition_points", 3, integer=True)
    avail = available_bytes()
    if n_points * BYTES_PER_RECOGNITION_POINT > USABLE_FRACTION * avail:
        raise ConfigError(f"{n_points} points would need about {n_points * BYTES_PER_RECOGNITION_POINT / 1024**3:.1f} "
                          f"GB ({avail / 1024**3:.1f} GB available): expected at most "
                          f"{int(USABLE_FRACTION * avail // BYTES_PER_RECOGNITION_POINT)} (the thesis uses about 170)",
                          parameter="recognition_points")
    if trials:
        _check_time(_recognition_params(params, n_points), n_points, len(shapes.RECOGNITION_NAMES),
                    "particles/recognition_points")


def _check_time(params: MupfParameters, n_points: int, n_models: int, parameter: str) -> None:
    """localize's time bound (check_run_time), naming this evaluation's own parameters (the points and windows
    are the protocol's or recognition_points, not localize's max_points / window)."""
    try:
        check_run_time(params, n_points, n_models)
    except ConfigError as exc:
        raise ConfigError(exc.detail, parameter=parameter) from None


def evaluate_recognition(*, trials: int = 1, n_points: int = 170, noise: float = 0.0,
                         params: MupfParameters = MupfParameters(), seed: int = 0, quiet: bool = True) -> dict:
    """Ch. 5 in simulation: for each of the six near-identical blocks, `trials` sets of n_points surface
    points at a Table 4.2-style pose; MUPF on every model (m = L/2), the lowest I_L names the object."""
    check_recognition(trials, n_points, params)
    check_number(seed, "seed", 0, 2 ** 63 - 1, integer=True)
    models = list(shapes.recognition_shapes())
    for m in models:
        m.build_field()
    rng = np.random.default_rng(seed)
    confusion = np.zeros((len(models), len(models)), dtype=int)
    rows = []
    jobs = [(i, k) for i in range(len(models)) for k in range(trials)]
    for i, _ in progress(jobs, total=len(jobs), desc="eval recognition", quiet=quiet, unit="trial"):
        trial = make_trial(models[i], n_points, noise, rng)
        s = int(rng.integers(2 ** 31))
        p = _recognition_params(params, n_points)
        res = [localize_mupf(m, trial.points, p, seed=s) for m in models]
        idx = [r.index for r in res]
        j = int(np.argmin(idx))
        confusion[i, j] += 1
        rows.append({"true": models[i].name, "chosen": models[j].name, "index_m": dict(zip([m.name for m in models],
                                                                                            idx)),
                     "seconds": float(sum(r.seconds for r in res))})
    return {"models": [m.name for m in models], "points": n_points, "noise_m": noise, "trials_per_object": trials,
            "confusion": confusion.tolist(), "correct": int(np.trace(confusion)), "total": int(confusion.sum()),
            "trials": rows, "thesis": "6/6 in simulation (about 170 noiseless points), 4/6 on real data"}


def _recognition_params(params: MupfParameters, n_points: int) -> MupfParameters:
    return replace(params, window=max(1, math.ceil(n_points / 2)))  # m = L / 2


def format_localization_table(doc: dict) -> str:
    """The Table 4.2 / 4.4 layout: per shape and method, RMS error (deg, m), mean I_L, mean / max time and
    successes, with the thesis' row beside ours; then the recognition confusion (when run)."""
    lines = [f"{'shape':<12}{'method':<15}{'err deg':>8}{'err m':>8}{'I_L mm':>8}{'time s':>13}{'cpu s mean/max':>15}{'succ.':>8}"
             f"   thesis (deg, m, I_L mm, s, succ./50)"]
    for name, per in doc.get("shapes", {}).items():
        for method, block in per.items():
            s = block["summary"]
            th = THESIS.get(method, {}).get(name)
            ref = ""
            if th is not None:
                ref = "   " + ", ".join("-" if v is None else (f"{v * 1000:.1f}" if i == 2 else f"{v:g}")
                                        for i, v in enumerate(th))
            lines.append(f"{name:<12}{method:<15}{s['rms_rotation_error_deg']:8.2f} {s['rms_translation_error_m']:7.4g}"
                         f" {s['mean_index_m'] * 1000:7.4g}{s['mean_seconds']:6.2f} /{s['max_seconds']:5.1f}"
                         f" {s['mean_cpu_seconds']:4.2f}/{s['max_cpu_seconds']:4.2f}"
                         f"{s['successes']:>4}/{s['trials']:<3}{ref}")
    rec = doc.get("recognition")
    if rec and rec["total"]:
        lines.append(f"recognition: {rec['correct']}/{rec['total']} correct ({rec['points']} points, noise "
                     f"{rec['noise_m']} m); thesis: {rec['thesis']}")
        lines.append("  confusion (rows true, columns chosen): " + " ".join(rec["models"]))
        for name, row in zip(rec["models"], rec["confusion"]):
            lines.append(f"  {name:<12}" + " ".join(f"{v:3d}" for v in row))
    return "\n".join(lines)
