"""Leave-one-user-out choice of the POI detectors' constants (the leave-one-user-out mode of `kinfu eval poi`).

Why: the defaults of GMM-AS and ZVC were chosen on the public users 1 and 4 of hand-polhemus; scored on
held-out users 2 and 3 the owners found pick-and-place recall 93.3 % (GMM-AS) and 86.7 % (ZVC) and ZVC's
ratio threshold on a cliff. A constant that generalises to a new person must be choosable on ONE person
and hold on another. For every constant of `STUDIES` (one at a time, the others at their defaults) and
every ordered pair (train user, test user), the value is chosen on the train user and scored on the test
user.

Choice rule: the train score of a value is the smallest precision or recall over the groups
(placements_removals, pick_and_place) the train user has, under every probe; the chosen value is the
centre of the longest run of consecutive grid values within `TIE` points of the best score (a plateau
centre is far from both cliffs; the best single value on one user is on an edge by construction).
The default constant is a value best on every user ("best_on_all_users"; each direction's test score
then shows how far a value chosen on one person carries to another).

Probes: "none" scores the recorded tasks; "quick-grasp" replays each task with its pauses shortened
(`quicken_pauses`: a sample moving at v is played 1 + 3·exp(−v / 0.1 m/s) times faster, so a still
hand goes 4× faster and transport is unchanged) — users 1 and 4 dwell 0.25-0.6 s at each action, and a
brisker person's short grasps are what the ratio rule and a duration-relative time floor miss. Both
users score at the data's ceiling for most values on the recorded tasks alone, so without the probe
the choice would be arbitrary.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from kinfu_cli.attention.detect import make_detector
from kinfu_cli.core.progress import progress
from kinfu_cli.core.trials import TrialMap
from kinfu_cli.evaluation.poi import find_tasks, score_pois, task_user
from kinfu_cli.io.polhemus import read_ground_truth, read_polhemus
from kinfu_cli.io.trajectory import Trajectory

#: (algorithm, constant, fixed parameters, grid in increasing order). One study per row.
STUDIES = (
    ("gmm-as", "reg_time", {}, (0.02, 0.03, 0.05, 0.07, 0.1, 0.15)),
    ("gmm-as", "poi_threshold", {}, (1.25, 1.5, 1.75, 2.0, 2.5)),
    ("zvc", "relative", {"rule": "relative"}, (0.15, 0.18, 0.2, 0.22, 0.25, 0.28, 0.3, 0.35, 0.4)),
    ("zvc", "threshold", {"rule": "ratio"}, (1.3, 1.4, 1.45, 1.5, 1.55, 1.6, 1.72)),
)
PROBES = ("none", "quick-grasp")
#: Train scores within this many percentage points of the best count as ties (one task of 20-110).
TIE = 0.5
#: quick-grasp probe: still samples replayed (1 + QUICK_FACTOR) times faster; speed scale (m/s).
QUICK_FACTOR = 3.0
QUICK_SPEED = 0.1


def quicken_pauses(traj: Trajectory, factor: float = QUICK_FACTOR, speed: float = QUICK_SPEED) -> Trajectory:
    """The same path with the hand's pauses played faster: the interval after a sample moving at v is
    divided by 1 + factor·exp(−v / speed); resampled at the original rate."""
    t = traj.t - traj.t[0]
    dt = np.diff(t)
    v = np.linalg.norm(np.diff(traj.positions, axis=0), axis=1) / np.maximum(dt, 1e-12)
    warped = np.r_[0.0, np.cumsum(dt / (1.0 + factor * np.exp(-v / speed)))]
    new_t = np.arange(0.0, warped[-1] + 1e-12, float(np.median(dt)))
    pos = np.column_stack([np.interp(new_t, warped, traj.positions[:, i]) for i in range(3)])
    return Trajectory(t=new_t + traj.t[0], positions=pos, frame=traj.frame, source=traj.source,
                      t0_ns=traj.t0_ns, meta={**traj.meta, "probe": "quick-grasp"})


def _probe(traj: Trajectory, probe: str) -> Trajectory:
    return quicken_pauses(traj) if probe == "quick-grasp" else traj


def _run_task(job: tuple) -> list[dict]:
    """Every study value on one task under every probe. Top level so it pickles."""
    task, studies, probes = job
    raw = read_polhemus(task.traj_path)
    gt = read_ground_truth(task.res_path)
    out = []
    for probe in probes:
        traj = _probe(raw, probe)
        for alg, name, fixed, grid in studies:
            for value in grid:
                det = make_detector(alg, {**fixed, name: value}).fit(traj)
                tp, fp, fn = score_pois(np.array([p.position for p in det.pois_]).reshape(-1, 3), gt)
                out.append({"algorithm": alg, "constant": name, "value": value, "probe": probe,
                            "user": task_user(task.name), "group": task.group, "tp": tp, "fp": fp, "fn": fn,
                            "changes": int(len(gt))})
    return out


def _task_trial(_shared, job: tuple) -> list[dict]:
    """_run_task as a trial of a `core.trials.TrialMap`."""
    return _run_task(job)


def _pr(rows: list[dict]) -> tuple[float, float]:
    tp, fp = sum(r["tp"] for r in rows), sum(r["fp"] for r in rows)
    ch, fn = sum(r["changes"] for r in rows), sum(r["fn"] for r in rows)
    return 100.0 * tp / (tp + fp) if tp + fp else 0.0, 100.0 * (ch - fn) / ch if ch else 0.0


def plateau_centre(values: list[float], scores: list[float], tie: float = TIE) -> float:
    """The centre of the longest run of consecutive values scoring within `tie` of the best (first run on ties)."""
    best = max(scores)
    runs, cur = [], []
    for v, s in zip(values, scores):
        if s >= best - tie:
            cur.append(v)
        else:
            if cur:
                runs.append(cur)
            cur = []
    if cur:
        runs.append(cur)
    run = max(runs, key=len)
    return run[(len(run) - 1) // 2] if len(run) % 2 else run[len(run) // 2 - 1]


def leave_one_user_out(dataset_dir: str | os.PathLike, algorithms: list[str] | None = None, workers: int = 1,
                       probes: tuple[str, ...] = PROBES, quiet: bool = True, studies: tuple = STUDIES,
                       map_trials: TrialMap | None = None) -> dict:
    """Choose each constant of STUDIES on one user, score it on another, every ordered pair of users.

    Returns {"users", "probes", "studies": [{"algorithm", "constant", "grid", "train_scores": {user: [...]},
    "directions": [{"train", "test", "chosen", "test_groups": {probe: {group: {"precision", "recall"}}}}]}]}
    (percent). A study needs two users with tasks; with fewer, "directions" is empty. map_trials: run the
    per-task jobs through this map (a Dask cluster) instead of `workers` local processes.
    """
    tasks = find_tasks(dataset_dir)
    studies = [s for s in studies if algorithms is None or s[0] in algorithms]
    jobs = [(t, studies, tuple(probes)) for t in tasks]
    rows: list[dict] = []
    if map_trials is not None:
        for res in map_trials(_task_trial, jobs):
            rows.extend(res)
    elif workers <= 1:
        for job in progress(jobs, total=len(jobs), desc="eval poi loo", quiet=quiet, unit="task"):
            rows.extend(_run_task(job))
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for res in progress(pool.map(_run_task, jobs, chunksize=2), total=len(jobs), desc="eval poi loo",
                                quiet=quiet, unit="task"):
                rows.extend(res)
    users = sorted({r["user"] for r in rows})
    out = {"users": users, "probes": list(probes), "tie_points": TIE, "studies": []}
    for alg, name, fixed, grid in studies:
        sel = [r for r in rows if r["algorithm"] == alg and r["constant"] == name]

        def cell(user, value, probe, group, sel=sel):
            return _pr([r for r in sel if r["user"] == user and r["value"] == value and r["probe"] == probe
                        and r["group"] == group])

        groups = {u: sorted({r["group"] for r in sel if r["user"] == u}) for u in users}
        train = {u: [min(min(cell(u, v, p, g)) for p in probes for g in groups[u]) for v in grid] for u in users}
        best_all = [v for i, v in enumerate(grid) if all(train[u][i] >= max(train[u]) for u in users)]
        study = {"algorithm": alg, "constant": name, "fixed": fixed, "grid": list(grid), "train_scores": train,
                 "best_on_all_users": best_all, "directions": []}
        for tr in users:
            chosen = plateau_centre(list(grid), train[tr])
            for te in users:
                if te == tr:
                    continue
                study["directions"].append({
                    "train": tr, "test": te, "chosen": chosen,
                    "test_groups": {p: {g: dict(zip(("precision", "recall"), cell(te, chosen, p, g)))
                                        for g in groups[te]} for p in probes}})
        out["studies"].append(study)
    return out


def format_loo(doc: dict) -> str:
    """The leave-one-user-out tables: per study, the train scores along the grid and each direction's test P / R."""
    lines = [f"Leave-one-user-out on {', '.join(doc['users'])} (probes: {', '.join(doc['probes'])}); "
             f"value = centre of the best plateau (±{doc['tie_points']:g} pt) on the train user"]
    for s in doc["studies"]:
        lines.append("")
        lines.append(f"{s['algorithm']} {s['constant']}" + (f" ({s['fixed']})" if s["fixed"] else ""))
        lines.append("  train score (min P/R over groups and probes, %) along " + " ".join(f"{v:g}" for v in s["grid"]))
        for u, sc in s["train_scores"].items():
            lines.append(f"    {u:<8}" + " ".join(f"{x:5.1f}" for x in sc))
        for d in s["directions"]:
            cells = "; ".join(f"{p} " + ", ".join(f"{g} {c['precision']:.1f} / {c['recall']:.1f}" for g, c in gs.items())
                              for p, gs in d["test_groups"].items())
            lines.append(f"  chosen on {d['train']}: {d['chosen']:g} -> {d['test']}: {cells}")
        lines.append("  best on every user: " + (", ".join(f"{v:g}" for v in s["best_on_all_users"]) or "none"))
    return "\n".join(lines)
