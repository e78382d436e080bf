"""The POI pipeline: a hand trajectory cut into tasks, a fresh GMM-AS or ZVC detector fitted on each.

`detect_pois` is the driver (`kinfu poi`): it checks every argument before reading the trajectory,
runs the detectors and returns a PoiDetection holding the POIs, the tasks, the fitted detectors and
the pois.json object. `detector_params` and `make_detector` build the detectors from one flat set of
parameters of both algorithms; the data-set evaluation (evaluation/poi.py) uses them too.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kinfu_cli.attention.gmm_as import MIN_POI_GAUSSIANS, GmmActivitySaliency
from kinfu_cli.attention.tasks import (MIN_TASK_S, SPLIT_GAP_S, TaskList, check_min_task, check_split_gap,
                                       check_workspace, detect_by_task, parse_workspace, task_entries)
from kinfu_cli.attention.zvc import PAPER_THRESHOLD, ZeroVelocityCrossing
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.pois import Poi, pois_document
from kinfu_cli.io.hand import load_hand_trajectory
from kinfu_cli.io.trajectory import Trajectory

Detector = GmmActivitySaliency | ZeroVelocityCrossing

# a hand at a table stays within a few metres (the 130 Polhemus tasks of ../shared/data/hand-polhemus span at most
# 3.1 m); a trajectory whose bulk (1st..99th percentile box) spans more is a robot's or a vehicle's path, or not in
# metres, and the detectors' metre constants (POI radius, spatial floors, ZVC radii) do not fit it
HAND_SPAN_WARN_M = 5.0
# a task whose hand stays within this (same box diagonal) never moved: ZVC's inner radius r1 (0.10 m) holds all of it
# and GMM-AS sees only the tracker's jitter; the smallest of the 130 Polhemus tasks spans 0.36 m
HAND_STILL_M = 0.10


def make_detector(algorithm: str, params: dict | None = None) -> Detector:
    """A fresh GmmActivitySaliency ("gmm-as") or ZeroVelocityCrossing ("zvc") with `params` (constructor keywords)."""
    params = dict(params or {})
    if algorithm == "gmm-as":
        return GmmActivitySaliency(**params)
    if algorithm == "zvc":
        return ZeroVelocityCrossing(**params)
    raise ConfigError(f"expected gmm-as, zvc or both, got {algorithm!r}", parameter="algorithm")


def detector_params(*, poi_threshold: float | None = None, neighbours: int | None = None,
                    bic_threshold: float | None = None, max_components: int | None = None,
                    selection: str | None = None, time_scale: str | float | None = None,
                    reg_space: float | None = None, reg_time: float | None = None, saliency: str | None = None,
                    threshold_mode: str | None = None, resample: int | None = None,
                    noise_floor: float | None = None, merge_distance: float | None = None, literal: bool = False, zvc_half_width: int | None = None,
                    zvc_threshold: float | None = None, zvc_r1: float | None = None, zvc_r2: float | None = None,
                    zvc_rule: str | None = None, zvc_relative: float | None = None,
                    radius: float | None = None) -> dict[str, dict]:
    """{"gmm-as": {...}, "zvc": {...}}: constructor keywords of both detectors from one flat set.

    The names are the GmmActivitySaliency ones, ZVC's with a `zvc_` prefix; `radius` goes to both.
    None leaves the detector's default. `literal` overrides with the paper read literally
    (GmmActivitySaliency.LITERAL; ZVC's ratio rule with ZVCTh = PAPER_THRESHOLD). A zvc_threshold without
    zvc_rule selects ZVC's ratio rule (the paper's absolute threshold).
    """
    given = {"poi_threshold": poi_threshold, "neighbours": neighbours, "bic_threshold": bic_threshold,
             "max_components": max_components, "selection": selection, "reg_space": reg_space,
             "reg_time": reg_time, "saliency": saliency, "threshold_mode": threshold_mode, "resample": resample,
             "noise_floor": noise_floor, "merge_distance": merge_distance, "time_scale": time_scale,
             "radius": radius}
    gmm_as = {k: v for k, v in given.items() if v is not None}
    zvc = {k: v for k, v in {"half_width": zvc_half_width, "threshold": zvc_threshold, "r1": zvc_r1, "r2": zvc_r2,
                             "rule": zvc_rule, "relative": zvc_relative, "radius": radius}.items()
           if v is not None}
    if literal:
        gmm_as.update(GmmActivitySaliency.LITERAL)
        zvc.update(threshold=PAPER_THRESHOLD, rule="ratio")
    return {"gmm-as": gmm_as, "zvc": zvc}


@dataclass
class PoiDetection:
    """What `detect_pois` found: the POIs of every task (ids 0.., extra "task"), the tasks, one fitted
    detector per task, and `document`, the pois.json object (pois, algorithm, parameters, frame, source,
    tasks, tasks_dropped, task_split)."""

    trajectory: Trajectory
    algorithm: str
    workspace: tuple[float, ...] | None
    tasks: TaskList
    detectors: list[Detector]
    pois: list[Poi]
    document: dict

    @property
    def whole_trajectory(self) -> bool:
        """True when one task holds every sample (nothing was cut away)."""
        return len(self.tasks) == 1 and self.tasks[0].samples == len(self.trajectory)


def _recording_times(pois: list[Poi], span: tuple | None) -> None:
    """Each POI's "recording_time_s", seconds from the recording's start (the clock of a time window), when its
    stamp lies in the recording's span; a POI's "time" counts from the first hand sample instead."""
    if not span or span[0] is None or span[1] is None:
        return
    for p in pois:
        stamp = p.extra.get("stamp_ns")
        if stamp is not None and span[0] - 1e9 <= stamp <= span[1] + 1e9:  # else another clock (sim time)
            p.extra["recording_time_s"] = round((stamp - span[0]) * 1e-9, 6)


def _span(positions: np.ndarray) -> float:
    """Diagonal of the 1st..99th percentile box of the positions (m): how far the hand's bulk moved."""
    lo, hi = np.percentile(positions, [1, 99], axis=0)
    return float(np.linalg.norm(hi - lo))


def span_warnings(traj: Trajectory) -> list[str]:
    """A warning when the trajectory spans far more than a person's reach (HAND_SPAN_WARN_M)."""
    span = _span(traj.positions)
    if span <= HAND_SPAN_WARN_M:
        return []
    return [f"the hand trajectory spans {span:.1f} m (diagonal of its 1st..99th percentile box), far more than a "
            f"person's reach at a table (under {HAND_SPAN_WARN_M:g} m): is it a hand, and in metres? A robot's or "
            f"vehicle's path gives POIs where it slowed down, not where a person acted"]


def empty_result_warnings(tasks: TaskList, detectors: list[Detector], whole: bool) -> list[str]:
    """Warnings for POIs missing, or made of noise, for a structural reason, per task: the hand never moved
    (HAND_STILL_M: whatever a detector finds there is tracker jitter), or GMM-AS fitted fewer than
    MIN_POI_GAUSSIANS Gaussians (none has a neighbour on each side). When no POI was found at all for no such
    reason, one warning says how close the detector came: an empty pois.json is refused downstream (kinfu nbv)."""
    out = []
    for task, det in zip(tasks, detectors):
        name = "" if whole else f"task {task.index}: "
        span = _span(task.trajectory.positions)
        if span < HAND_STILL_M:
            n = len(det.pois_)
            found = f"its {n} POI(s) come from tracker jitter, not from actions" if n else "no POI can be found"
            out.append(f"{name}the hand stays within {100 * span:.1f} cm (diagonal of its 1st..99th percentile box) "
                       f"over {task.duration:.1f} s: it never moved (a still or lost tracker?), so {found}")
        elif isinstance(det, ZeroVelocityCrossing) and 2 * det.half_width + 1 > task.samples:
            n = len(det.pois_)
            found = f"its {n} POI(s) come from a path averaged flat" if n else "no POI can be found"
            out.append(f"{name}ZVC's mean filter spans 2B+1 = {2 * det.half_width + 1} samples (zvc_half_width B = "
                       f"{det.half_width}), more than the task's {task.samples} samples: it averages the task's "
                       f"path flat, so {found}")
        elif getattr(det, "n_components_", MIN_POI_GAUSSIANS) < MIN_POI_GAUSSIANS:
            out.append(f"{name}GMM-AS fitted K = {det.n_components_} Gaussian(s), and a POI is a Gaussian between "
                       f"two others (the first and last are skipped), so it cannot give one: the path holds no "
                       f"dwell between an approach and a departure (a single move, or too few samples)")
    if not out and not any(det.pois_ for det in detectors):
        out.append(f"no POI found: {_closest_miss(detectors)}")
    return out


def _closest_miss(detectors: list[Detector]) -> str:
    """How near the fitted detectors (all of one algorithm) came to a POI, in words."""
    if isinstance(detectors[0], ZeroVelocityCrossing):
        with np.errstate(divide="ignore", invalid="ignore"):  # a zero limit where the hand stood still
            ratios = [d.speed_r1_ / d.slow_limit_ for d in detectors if np.any(d.slow_limit_ > 0)]
        finite = [float(np.min(r[np.isfinite(r)])) for r in ratios if np.any(np.isfinite(r))]
        d = detectors[0]
        if not finite:  # a zero limit throughout: a ratio to it says nothing (it read "nan x that limit")
            return (f"ZVC's slow limit ({d.rule_} rule) is zero throughout: the hand's mean-filtered path never "
                    f"moved, so no sample is slower than it (zvc_half_width B = {d.half_width} averages "
                    f"2B+1 samples)")
        slowest = min(finite)
        return (f"the hand's mean speed within r1 = {d.r1:g} m never fell below ZVC's slow limit ({d.rule_} rule); at "
                f"its slowest it was {slowest:.2f} x that limit, so it never dwelt anywhere (zvc_relative or "
                f"zvc_threshold set the limit)")
    with np.errstate(divide="ignore", invalid="ignore"):  # NaN thresholds of the first and last Gaussian
        closest = max(float(np.nanmax(d.saliency_ / d.thresholds_)) for d in detectors)
    return (f"no GMM-AS Gaussian is more salient than POITh = {detectors[0].poi_threshold:g} x its neighbours' mean; "
            f"the closest reached {closest:.2f} x that threshold (poi_threshold sets it)")


def check_window(detector: Detector, samples: int) -> None:
    """ConfigError naming zvc_half_width when ZVC's mean filter (2B+1 samples) is longer than the whole trajectory
    of `samples` samples: it averages the path flat (no speed anywhere, no POI, the slow limit zero)."""
    if isinstance(detector, ZeroVelocityCrossing) and 2 * int(detector.half_width) + 1 > samples:
        raise ConfigError(f"a mean filter of 2B+1 = {2 * int(detector.half_width) + 1} samples is longer than the "
                          f"trajectory's {samples} samples; expected B at most {max(0, (samples - 1) // 2)}",
                          parameter="zvc_half_width")


def check_detection(algorithm: str = "gmm-as", params: dict | None = None, *,
                    workspace: str | Sequence[float] | None = None, split_gap: float | None = SPLIT_GAP_S,
                    min_task: float = MIN_TASK_S) -> tuple[float, ...] | None:
    """The arguments of `detect_pois` checked before any trajectory is read (ConfigError naming the first bad
    one); returns the workspace box (None: everywhere)."""
    box = parse_workspace(workspace) if isinstance(workspace, str) else check_workspace(workspace)
    check_split_gap(split_gap)
    check_min_task(min_task)
    make_detector(algorithm, params).check_params()
    return box


def detect_pois(source: str | os.PathLike | Trajectory, algorithm: str = "gmm-as", params: dict | None = None, *,
                workspace: str | Sequence[float] | None = None, split_gap: float | None = SPLIT_GAP_S,
                min_task: float = MIN_TASK_S, hand_topic: str | None = None, hand_frame: str | None = None,
                world_frame: str | None = None, quiet: bool = True) -> PoiDetection:
    """Points of interest of a hand trajectory, each task (attention/tasks.py) fitted on its own.

    source: a Trajectory, a Polhemus `.traj` file or a recording (read with hand_topic / hand_frame /
    world_frame, see io.hand.load_hand_trajectory). params: constructor keywords of the `algorithm`
    detector (one entry of `detector_params`). workspace: a box (x0, y0, z0, x1, y1, z1) in metres or
    its text 'x0,y0,z0,x1,y1,z1'; None = everywhere. Every argument is checked before the trajectory
    is read. Raises ConfigError when no task is left.
    """
    box = check_detection(algorithm, params, workspace=workspace, split_gap=split_gap, min_task=min_task)
    if isinstance(source, Trajectory):
        traj, source_name = source, source.source
    else:
        traj = load_hand_trajectory(source, hand_topic=hand_topic, hand_frame=hand_frame, world_frame=world_frame)
        source_name = str(source)
    check_window(make_detector(algorithm, params), len(traj))
    tasks, detectors, pois = detect_by_task(traj, lambda: make_detector(algorithm, params), box, split_gap,
                                            min_task, quiet=quiet)
    _recording_times(pois, traj.meta.get("recording_span_ns"))
    recorded = dict(detectors[0].get_params())
    if algorithm == "gmm-as":
        recorded["n_components"] = int(sum(d.n_components_ for d in detectors))  # per task in "tasks"
    document = pois_document(pois, algorithm, recorded, frame=traj.frame, source=source_name)
    document["tasks"] = task_entries(tasks, detectors)
    whole = len(tasks) == 1 and tasks[0].samples == len(traj)
    document["warnings"] = (list(traj.meta.get("recording_problems", [])) + span_warnings(traj)
                            + empty_result_warnings(tasks, detectors, whole))
    document["tasks_dropped"] = tasks.dropped
    document["task_split"] = {"workspace": list(box) if box else None,
                              "split_gap": None if split_gap is None else float(split_gap),
                              "min_task": float(min_task)}
    return PoiDetection(trajectory=traj, algorithm=algorithm, workspace=box, tasks=tasks, detectors=detectors,
                        pois=pois, document=document)
