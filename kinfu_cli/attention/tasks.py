"""Cut a long hand stream into tasks, as the paper's recorder does, before POI detection.

Monica et al. RAS 2016 §4.4/§6: "Task trajectories are automatically recorded when the user hand is
inside the bounding box of the workspace ... When the hand exits the bounding box, the trajectory is
analyzed." GMM-AS normalises time by the task duration, resamples every task to a fixed number of
samples and floors the time std at a share of the duration (attention/gmm_as.py), so it must see ONE task at
a time: fed minutes of stream with several actions, the actions blur into a few Gaussians.

A task is a maximal run of samples inside the workspace box (axis-aligned, the trajectory's frame,
metres, bounds inclusive; None = everywhere) with no pause between consecutive samples longer than
`split_gap` seconds (a tracker that stops streaming while the hand is away). Runs shorter than
`min_task` seconds or `min_samples` samples (the hand crossing a corner of the box, tracker glitches)
are dropped and counted. Each Task keeps its samples as a Trajectory on the SAME clock (t, t0_ns) as
the input, so POI times and stamps of a task read like those of the whole stream.

The POI driver (attention/detect.py) writes the result into pois.json: each POI gains "task" (its task
index), and the file gains "tasks" (task_entries: index, t_start, t_end [s, the POIs' clock], samples,
first_sample, last_sample, stamp_ns_start/end from recordings, n_pois, n_components for GMM-AS),
"tasks_dropped" (runs too short) and "task_split" (the workspace, split_gap and min_task used).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.pois import Poi
from kinfu_cli.core.progress import progress
from kinfu_cli.io.trajectory import Trajectory

#: Default minimum task: real tasks last 0.9 s and more (hand-polhemus); a hand crossing a corner of
#: the box or a tracker glitch lasts a fraction of that.
MIN_TASK_S = 0.5
MIN_SAMPLES = 5
#: Default pause that starts a new task (seconds; 0 = never split on pauses).
SPLIT_GAP_S = 2.0


@dataclass
class Task:
    """One task: samples [start, stop) of the input trajectory (`stop` exclusive)."""

    index: int
    start: int
    stop: int
    t_start: float
    t_end: float
    trajectory: Trajectory = field(repr=False)

    @property
    def samples(self) -> int:
        return self.stop - self.start

    @property
    def duration(self) -> float:
        return self.t_end - self.t_start

    def to_dict(self) -> dict:
        """JSON entry (t on the input trajectory's clock, seconds; `last_sample` inclusive)."""
        d = {"index": int(self.index), "t_start": float(self.t_start), "t_end": float(self.t_end),
             "samples": int(self.samples), "first_sample": int(self.start), "last_sample": int(self.stop - 1)}
        t0 = self.trajectory.t0_ns
        if t0:
            d["stamp_ns_start"] = int(t0 + round(self.t_start * 1e9))
            d["stamp_ns_end"] = int(t0 + round(self.t_end * 1e9))
        return d


class TaskList(list):
    """The tasks found (a list of Task) plus what was left out.

    dropped: runs removed as too short; inside: samples inside the workspace (all of them without one).
    """

    def __init__(self, tasks=(), dropped: int = 0, inside: int = 0) -> None:
        super().__init__(tasks)
        self.dropped = int(dropped)
        self.inside = int(inside)


def parse_workspace(text: str | None) -> tuple[float, ...] | None:
    """'x0,y0,z0,x1,y1,z1' (metres) -> 6 floats, or None for None/''; errors name `workspace`."""
    if text is None or not str(text).strip():
        return None
    parts = [p for p in str(text).replace(" ", ",").split(",") if p]
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 6 or not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"expected six numbers x0,y0,z0,x1,y1,z1 (metres), got {text!r}", parameter="workspace")
    return check_workspace(vals)


def check_workspace(workspace) -> tuple[float, ...] | None:
    """Validate a (x0, y0, z0, x1, y1, z1) box (None passes); errors name `workspace`."""
    if workspace is None:
        return None
    try:
        w = np.asarray(workspace, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        w = np.zeros(0)
    if w.shape != (6,) or not np.all(np.isfinite(w)):
        raise ConfigError(f"expected six finite numbers x0,y0,z0,x1,y1,z1 (metres), got {workspace!r}",
                          parameter="workspace")
    if not np.all(w[:3] < w[3:]):
        raise ConfigError(f"expected x0 < x1, y0 < y1, z0 < z1 (min corner first), "
                          f"got {','.join(f'{v:g}' for v in w)}", parameter="workspace")
    return tuple(float(v) for v in w)


def check_split_gap(split_gap) -> None:
    """`split_gap` is None or seconds >= 0 (0 = never split on pauses)."""
    # finite: inf was written to pois.json as Infinity, which is no JSON (0 already means never)
    if split_gap is not None and not (isinstance(split_gap, (int, float)) and 0 <= split_gap < math.inf):
        raise ConfigError(f"expected finite seconds >= 0 (0 = never split on pauses), got {split_gap}",
                          parameter="split_gap")


def check_min_task(min_task) -> None:
    """`min_task` is seconds >= 0."""
    if not (isinstance(min_task, (int, float)) and 0 <= min_task < math.inf):
        raise ConfigError(f"expected finite seconds >= 0, got {min_task}", parameter="min_task")


def _check_limits(split_gap, min_task, min_samples) -> None:
    check_split_gap(split_gap)
    check_min_task(min_task)
    if int(min_samples) != min_samples or min_samples < 1:
        raise ConfigError(f"expected an integer >= 1, got {min_samples!r}", parameter="min_samples")


def inside_workspace(positions: np.ndarray, workspace) -> np.ndarray:
    """(N,) bool: positions (N, 3) inside the box (bounds inclusive); all True for None."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if workspace is None:
        return np.ones(len(p), bool)
    w = np.asarray(workspace, dtype=np.float64)
    return np.all((p >= w[:3]) & (p <= w[3:]), axis=1)


def split_tasks(traj: Trajectory, workspace=None, split_gap: float | None = SPLIT_GAP_S,
                min_task: float = MIN_TASK_S, min_samples: int = MIN_SAMPLES) -> TaskList:
    """Tasks of `traj`: maximal runs inside `workspace` without a pause longer than `split_gap`.

    workspace: (x0, y0, z0, x1, y1, z1) metres in traj.frame, or None (everywhere).
    split_gap: split where consecutive samples are more than this many seconds apart; 0 or None = never.
    Runs lasting less than `min_task` seconds (t_end - t_start) or with fewer than `min_samples`
    samples are dropped (counted in `.dropped`). Returns a TaskList (index 0.. in time order).
    """
    workspace = check_workspace(workspace)
    _check_limits(split_gap, min_task, min_samples)
    n = len(traj)
    inside = inside_workspace(traj.positions, workspace)
    if n == 0:
        return TaskList()
    brk = np.zeros(max(n - 1, 0), bool)  # brk[i]: a run cannot continue from sample i to i + 1
    if split_gap:
        brk |= np.diff(traj.t) > split_gap
    inn = inside.astype(np.int8)
    starts = np.flatnonzero(inside & np.r_[True, brk | (inn[:-1] == 0)])
    stops = np.flatnonzero(inside & np.r_[brk | (inn[1:] == 0), True]) + 1
    dur = traj.t[stops - 1] - traj.t[starts] if len(starts) else np.zeros(0)
    keep = (stops - starts >= min_samples) & (dur >= min_task)
    tasks = TaskList(dropped=int((~keep).sum()), inside=int(inside.sum()))
    for a, b in zip(starts[keep], stops[keep]):
        sub = Trajectory(t=traj.t[a:b], positions=traj.positions[a:b],
                         rotations=None if traj.rotations is None else traj.rotations[a:b],
                         frame=traj.frame, source=traj.source, t0_ns=traj.t0_ns,
                         meta={**traj.meta, "task": len(tasks), "task_samples": [int(a), int(b)]})
        tasks.append(Task(index=len(tasks), start=int(a), stop=int(b), t_start=float(traj.t[a]),
                          t_end=float(traj.t[b - 1]), trajectory=sub))
    return tasks


def require_tasks(tasks: TaskList, traj: Trajectory, workspace=None, split_gap: float | None = SPLIT_GAP_S,
                  min_task: float = MIN_TASK_S) -> TaskList:
    """Return `tasks`, or raise a one-line ConfigError saying why there is none."""
    if tasks:
        return tasks
    name = traj.source or "trajectory"
    if workspace is not None and tasks.inside == 0:
        lo, hi = traj.positions.min(axis=0), traj.positions.max(axis=0)
        box = ",".join(f"{v:.3f}" for v in (*lo, *hi))
        ws = ",".join(f"{v:g}" for v in workspace)
        raise ConfigError(f"box {ws} contains no sample of {name}, whose bounding box is {box} "
                          f"(x0,y0,z0,x1,y1,z1, metres, frame {traj.frame or '?'})", parameter="workspace")
    where = "inside the workspace" if workspace is not None else "in the trajectory"
    gap = f", split at pauses > {split_gap:g} s (split_gap)" if split_gap else ""
    raise ConfigError(f"{name}: no task left: all {tasks.dropped} run(s) of samples {where}{gap} last less than "
                      f"{min_task:g} s (min_task) or have too few samples")


def detect_by_task(traj: Trajectory, new_detector: Callable[[], object], workspace=None,
                   split_gap: float | None = SPLIT_GAP_S, min_task: float = MIN_TASK_S,
                   min_samples: int = MIN_SAMPLES, quiet: bool = True) -> tuple[TaskList, list, list[Poi]]:
    """Split `traj` into tasks and fit a fresh detector (`new_detector()`, GMM-AS or ZVC) on each.

    Returns (tasks, fitted detectors, POIs): the POIs concatenated in task order, ids renumbered 0..,
    each with extra "task" (its task index) and, when the trajectory has absolute stamps, "stamp_ns".
    Raises ConfigError (require_tasks) when no task is left.
    """
    tasks = split_tasks(traj, workspace, split_gap=split_gap, min_task=min_task, min_samples=min_samples)
    require_tasks(tasks, traj, workspace, split_gap, min_task)
    detectors, pois = [], []
    for task in progress(tasks, total=len(tasks), desc="poi", quiet=quiet or len(tasks) < 2, unit="task"):
        det = new_detector().fit(task.trajectory)
        for p in det.pois_:
            p.id = len(pois)
            if traj.t0_ns:
                p.extra["stamp_ns"] = int(traj.t0_ns + round(p.time * 1e9))
            p.extra["task"] = task.index
            pois.append(p)
        detectors.append(det)
    return tasks, detectors, pois


def task_entries(tasks: TaskList, detectors: list) -> list[dict]:
    """The pois.json "tasks" list: Task.to_dict() + n_pois (+ n_components for GMM-AS)."""
    out = []
    for task, det in zip(tasks, detectors):
        e = task.to_dict()
        e["n_pois"] = len(det.pois_)
        if hasattr(det, "n_components_"):
            e["n_components"] = int(det.n_components_)
        out.append(e)
    return out
