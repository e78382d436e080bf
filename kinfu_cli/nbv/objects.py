"""Object-driven view planning, thesis ch. 3 Alg. 4 (Monica & Aleotti, Auton. Robots 2017).

1. Contour points with view directions (kinfu_cli.nbv.contours).
2. Per contour point 5 directions (its frontier normal and 4 more at `cone_deg` = 15 deg around it) x 8
   rolls (45 deg) at `distance` = 0.8 m, looking at the point: 40 candidate poses.
3. Segments of the surface with saliency (kinfu_cli.segmentation), most salient first.
4. FindNear: a contour point belongs to the segment of its nearest surface point.
5. The candidates of the current segment are scored by a `scorer(poses, center, radius) -> (V,)` on the
   sphere around the segment's bounding sphere enlarged by `margin` = 0.2 m (default scorer: the NBV
   module's count of rays ending on unknown voxels in that sphere); the best pose whose score exceeds
   `score_threshold` is returned; otherwise the next segment is tried; otherwise no view.

`plan_standard_views` is the baseline of thesis Table 3.1: no segmentation, every candidate scored on the
whole environment. Both report how many candidates they ray-cast.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.fusion.up import z_to_up_rotation
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.nbv.contours import Contours, extract_contours
from kinfu_cli.nbv.ranking import as_ray_volume, score_views
from kinfu_cli.nbv.raycast import RayVolume
from kinfu_cli.segmentation.pipeline import SegmentOptions, SegmentResult, analyse_volume

Scorer = Callable[[np.ndarray, np.ndarray, float], np.ndarray]

# Candidate views of a contour point (thesis Alg. 4), the defaults of every planner here.
VIEW_DISTANCE = 0.8  # sensor distance from the contour point (m)
CONE_DEG = 15.0  # tilt of the 4 extra directions about the frontier normal
N_DIRECTIONS = 5
N_ROLLS = 8


def _look_at_rolls(positions: np.ndarray, targets: np.ndarray, rolls: np.ndarray, up=None) -> np.ndarray:
    """(P * R, 4, 4) camera-to-world poses (optical frame: z forward, y down) for each position x roll; roll 0
    has the image upright for the world's `up` (default z)."""
    R_up = z_to_up_rotation(up)
    z = targets - positions
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = np.cross(z, R_up[:, 2])
    bad = np.linalg.norm(x, axis=1) < 1e-6
    x[bad] = np.cross(z[bad], R_up[:, 0])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    c, s = np.cos(rolls), np.sin(rolls)
    P, R = len(positions), len(rolls)
    xr = c[None, :, None] * x[:, None, :] + s[None, :, None] * y[:, None, :]
    yr = -s[None, :, None] * x[:, None, :] + c[None, :, None] * y[:, None, :]
    T = np.zeros((P, R, 4, 4))
    T[..., :3, 0] = xr
    T[..., :3, 1] = yr
    T[..., :3, 2] = z[:, None, :]
    T[..., :3, 3] = positions[:, None, :]
    T[..., 3, 3] = 1.0
    return T.reshape(P * R, 4, 4)


def contour_viewpoints(points: np.ndarray, directions: np.ndarray, *, distance: float = VIEW_DISTANCE,
                       cone_deg: float = CONE_DEG, n_directions: int = N_DIRECTIONS, n_rolls: int = N_ROLLS,
                       up=None) -> tuple[np.ndarray, np.ndarray]:
    """Candidate poses for contour points: (poses (M * n_directions * n_rolls, 4, 4), owner (same,) index of
    the contour point). Direction 0 is the frontier normal; the others are tilted by `cone_deg` about it
    at equal azimuths. up: the world's up (default z); the candidates turn with it (fusion.up.z_to_up_rotation)."""
    if not distance > 0:
        raise ConfigError(f"must be > 0 m, got {distance}", parameter="distance")
    if n_directions < 1 or n_rolls < 1:
        raise ConfigError(f"must be >= 1, got {n_directions}, {n_rolls}", parameter="n_directions/n_rolls")
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    M = len(p)
    if M == 0:
        return np.zeros((0, 4, 4)), np.zeros(0, np.int64)
    R_up = z_to_up_rotation(up)
    a = np.where(np.abs((n @ R_up)[:, 0:1]) < 0.9, R_up[:, 0], R_up[:, 1])  # the z-up choice, turned with up
    u = np.cross(n, a)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(n, u)
    dirs = [n]
    t = np.radians(cone_deg)
    for k in range(n_directions - 1):
        phi = 2 * np.pi * k / (n_directions - 1)
        dirs.append(np.cos(t) * n + np.sin(t) * (np.cos(phi) * u + np.sin(phi) * v))
    D = np.stack(dirs, axis=1).reshape(-1, 3)  # (M * nd, 3)
    targets = np.repeat(p, n_directions, axis=0)
    rolls = 2 * np.pi * np.arange(n_rolls) / n_rolls
    poses = _look_at_rolls(targets + distance * D, targets, rolls, up)
    owner = np.repeat(np.arange(M), n_directions * n_rolls)
    return poses, owner


def find_near(contour_points: np.ndarray, surface_points: np.ndarray, surface_labels: np.ndarray) -> np.ndarray:
    """Segment label of each contour point = label of its nearest surface point (thesis FindNear)."""
    if len(contour_points) == 0:
        return np.zeros(0, np.int64)
    _, i = cKDTree(surface_points).query(contour_points)
    return np.asarray(surface_labels)[i]


@dataclass
class SegmentAttempt:
    """One segment the planner tried, most salient first. touches_grid_faces: the grid's faces that cut the segment
    (segmentation's grid_faces); rejected: its candidates rejected per reason, when the scorer says (`nbv_scorer`)."""

    segment_id: int
    saliency: float
    center: list
    radius: float
    contour_points: int
    candidates: int
    best_score: float
    accepted: bool
    touches_grid_faces: list = field(default_factory=list)
    rejected: dict | None = None

    @property
    def valid(self) -> int | None:
        """Candidates whose sensor position passed the scorer's checks (None when the scorer does not say)."""
        return None if self.rejected is None else self.candidates - sum(self.rejected.values())


@dataclass
class ObjectPlan:
    """Result of `plan_object_views`: `pose` (4x4 camera-to-world) or None when no view beats the threshold."""

    pose: np.ndarray | None
    score: float
    segment_id: int | None
    region_center: np.ndarray | None
    region_radius: float | None
    candidates_total: int  # every candidate pose generated (all contour points x 40)
    candidates_evaluated: int  # poses actually ray-cast
    attempts: list[SegmentAttempt] = field(default_factory=list)
    ranked_poses: np.ndarray | None = None  # the chosen segment's poses, best first
    ranked_scores: np.ndarray | None = None
    timing: dict = field(default_factory=dict)

    def to_json(self, top: int = 10) -> dict:
        return {
            "pose": None if self.pose is None else self.pose.tolist(), "score": self.score,
            "segment_id": self.segment_id,
            "region": None if self.region_center is None else {"center": self.region_center.tolist(),
                                                               "radius": self.region_radius},
            "candidates_total": self.candidates_total, "candidates_evaluated": self.candidates_evaluated,
            "attempts": [a.__dict__ for a in self.attempts],
            "views": [] if self.ranked_poses is None else [
                {"pose": self.ranked_poses[i].tolist(), "score": float(self.ranked_scores[i])}
                for i in range(min(top, len(self.ranked_poses)))],
            "timing_s": self.timing,
        }


def nbv_scorer(grid: TernaryGrid | RayVolume, camera: CameraModel, gain: str = "unknown",
               table_z: float | None = None, *, reject_unknown: bool = True, optimistic: bool = False,
               up=None, tally: dict | None = None) -> Scorer:
    """The NBV module's ray-casting score (rays ending on unknown voxels inside the region sphere).
    reject_unknown: a sensor position in unknown space scores 0 (the paper; a simulated arm without a motion
    planner may pass False); optimistic: unknown voxels outside the region do not stop rays; table_z: the
    table's height along `up` (default z); tally: when given, counts the views scored ("views", "valid") and
    rejected (by reason). The scorer's `last_rejected` holds the last call's rejections per reason
    (`plan_object_views` records them per segment)."""
    vol = as_ray_volume(grid)

    def score(poses: np.ndarray, center: np.ndarray, radius: float) -> np.ndarray:
        s = score_views(vol, poses, camera, center, radius, gain, table_z=table_z, reject_unknown=reject_unknown,
                        optimistic=optimistic, up=up)
        score.last_rejected = s.rejected()
        if tally is not None:
            tally["views"] = tally.get("views", 0) + len(s.reasons)
            tally["valid"] = tally.get("valid", 0) + int(s.valid.sum())
            for reason, n in s.rejected().items():
                tally[reason] = tally.get(reason, 0) + n
        return np.asarray(s.gain, dtype=float)

    score.last_rejected = None
    return score


def not_attempted(poses: np.ndarray, taken, *, shift: float = 0.05, turn_deg: float = 10.0) -> np.ndarray:
    """(V,) bool: candidate poses that are NOT within `shift` metres and `turn_deg` degrees (optical axis; the
    roll is ignored) of any pose in `taken` (K, 4, 4) -- the thesis skips viewpoints already attempted."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    keep = np.ones(len(poses), dtype=bool)
    if taken is None or len(taken) == 0 or len(poses) == 0:
        return keep
    taken = np.asarray(taken, dtype=np.float64).reshape(-1, 4, 4)
    d = np.linalg.norm(poses[:, None, :3, 3] - taken[None, :, :3, 3], axis=2)
    c = np.einsum("vi,ki->vk", poses[:, :3, 2], taken[:, :3, 2])
    near = (d < shift) & (c > np.cos(np.radians(turn_deg)))
    return ~near.any(axis=1)


def plan_object_views(segments: SegmentResult, contours: Contours, scorer: Scorer, *, score_threshold: float = 0.0,
                      margin: float = 0.2, distance: float = VIEW_DISTANCE, cone_deg: float = CONE_DEG,
                      n_directions: int = N_DIRECTIONS, n_rolls: int = N_ROLLS, max_segments: int | None = None,
                      exclude=None, exclude_shift: float = 0.05, exclude_turn_deg: float = 10.0,
                      up=None) -> ObjectPlan:
    """Thesis Alg. 4 on precomputed `segments` and `contours`: the best pose of the most salient segment
    with score > score_threshold.

    scorer(poses (V, 4, 4), center (3,), radius) -> scores (V,); exclude: poses (K, 4, 4) already taken:
    candidates within `exclude_shift` m and `exclude_turn_deg` of one are neither cast nor chosen; up: the
    world's up (default z) for the candidates' orientation. Returns an ObjectPlan with the number of
    candidates generated and ray-cast.
    """
    t0 = time.perf_counter()
    poses, owner = contour_viewpoints(contours.positions, contours.directions, distance=distance,
                                      cone_deg=cone_deg, n_directions=n_directions, n_rolls=n_rolls, up=up)
    free = not_attempted(poses, exclude, shift=exclude_shift, turn_deg=exclude_turn_deg)
    seg = segments.segmentation
    cut = getattr(segments, "grid_faces", {})
    near = find_near(contours.positions, seg.points, seg.labels)
    plan = ObjectPlan(None, 0.0, None, None, None, int(len(poses)), 0)
    plan.timing["views_generation"] = time.perf_counter() - t0
    t_eval = 0.0
    for rank, s in enumerate(segments.objects):  # background segments (a wall) are not worth a view
        if max_segments is not None and rank >= max_segments:
            break
        cp = np.flatnonzero(near == s.id)
        center = np.asarray(s.box.center, dtype=np.float64)
        radius = float(s.bounding_radius + margin)
        faces = list(cut.get(s.id, []))
        if len(cp) == 0:
            plan.attempts.append(SegmentAttempt(s.id, s.saliency, center.tolist(), radius, 0, 0, 0.0, False, faces))
            continue
        sel = np.flatnonzero(np.isin(owner, cp) & free)
        if len(sel) == 0:
            plan.attempts.append(SegmentAttempt(s.id, s.saliency, center.tolist(), radius, int(len(cp)), 0, 0.0,
                                                False, faces))
            continue
        t = time.perf_counter()
        scores = np.asarray(scorer(poses[sel], center, radius), dtype=float)
        t_eval += time.perf_counter() - t
        plan.candidates_evaluated += int(len(sel))
        order = np.argsort(-scores, kind="stable")
        best = float(scores[order[0]])
        ok = best > score_threshold
        rejected = getattr(scorer, "last_rejected", None)
        plan.attempts.append(SegmentAttempt(s.id, s.saliency, center.tolist(), radius, int(len(cp)), int(len(sel)),
                                            best, ok, faces, None if rejected is None else dict(rejected)))
        if ok:
            plan.pose = poses[sel[order[0]]]
            plan.score = best
            plan.segment_id = s.id
            plan.region_center = center
            plan.region_radius = radius
            plan.ranked_poses = poses[sel[order]]
            plan.ranked_scores = scores[order]
            break
    plan.timing["views_evaluation"] = t_eval
    plan.timing["total"] = time.perf_counter() - t0
    return plan


def plan_standard_views(contours: Contours, scorer: Scorer, region_center, region_radius: float, *,
                        score_threshold: float = 0.0, distance: float = VIEW_DISTANCE, cone_deg: float = CONE_DEG,
                        n_directions: int = N_DIRECTIONS, n_rolls: int = N_ROLLS, exclude=None,
                        exclude_shift: float = 0.05,
                        exclude_turn_deg: float = 10.0) -> ObjectPlan:
    """The "standard" baseline: every contour candidate scored on the whole environment sphere
    (candidates near an `exclude` pose, already taken, are skipped as in `plan_object_views`)."""
    t0 = time.perf_counter()
    poses, _ = contour_viewpoints(contours.positions, contours.directions, distance=distance, cone_deg=cone_deg,
                                  n_directions=n_directions, n_rolls=n_rolls)
    poses = poses[not_attempted(poses, exclude, shift=exclude_shift, turn_deg=exclude_turn_deg)]
    plan = ObjectPlan(None, 0.0, None, np.asarray(region_center, float), float(region_radius), int(len(poses)), 0)
    if len(poses):
        t = time.perf_counter()
        scores = np.asarray(scorer(poses, np.asarray(region_center, float), float(region_radius)), dtype=float)
        plan.timing["views_evaluation"] = time.perf_counter() - t
        plan.candidates_evaluated = int(len(poses))
        order = np.argsort(-scores, kind="stable")
        plan.ranked_poses, plan.ranked_scores = poses[order], scores[order]
        if scores[order[0]] > score_threshold:
            plan.pose, plan.score = poses[order[0]], float(scores[order[0]])
    plan.timing["total"] = time.perf_counter() - t0
    return plan


# thesis W_th (ch. 3, contour extraction): observations before a voxel counts as known at the contours
W_TH = 5.0


def _weights(volume, weights: np.ndarray | None) -> np.ndarray | None:
    """The dense fusion weights: the caller's when it has them already (one extraction serves score and
    contours), else the volume's; None for a ternary grid."""
    if weights is not None or not hasattr(volume, "weights"):
        return weights
    return volume.weights()


def known_grid(volume: TernaryVolume | TernaryGrid, w_th: float = W_TH, weights: np.ndarray | None = None
               ) -> tuple[TernaryGrid, bool]:
    """The ternary grid of the object-driven planner (thesis ch. 3): voxels observed fewer than `w_th` times are
    unknown, for the ray-cast score as for the contours. The flag says whether weights were there to apply it
    (a ternary grid file has none: then known = observed once)."""
    grid = volume.ternary_grid() if hasattr(volume, "ternary_grid") else volume
    weights = _weights(volume, weights)
    if weights is None:
        return grid, False
    return replace(grid, labels=np.where(weights >= w_th, grid.labels, np.int8(0))), True


def volume_contours(volume: TernaryVolume | TernaryGrid, w_th: float = W_TH, weights: np.ndarray | None = None
                    ) -> tuple[Contours, bool]:
    """Contours (`nbv.contours`) with the thesis' W_th applied: a voxel is known only once observed `w_th` times, so a
    surface seen in one or two noisy frames still borders unknown space and keeps its contour points.
    Needs the fusion weights, which a fused volume (volume.npz) has and a ternary grid (ternary.npz) has not;
    the flag says whether W_th could be applied (without weights every labelled voxel counts as known)."""
    grid = volume.ternary_grid() if hasattr(volume, "ternary_grid") else volume
    weights = _weights(volume, weights)
    contours = extract_contours(grid.labels, grid.origin, grid.voxel_size, weights=weights, w_th=w_th)
    return contours, weights is not None


def plan_object_views_for_volume(volume: TernaryVolume | TernaryGrid, camera: CameraModel, *,
                                 scorer: Scorer | None = None, score_threshold: float = 0.0, w_th: float = W_TH,
                                 segment_options: SegmentOptions | None = None, table_z: float | None = None,
                                 up=None, weights: np.ndarray | None = None, **kwargs) -> ObjectPlan:
    """Everything from a volume (fusion TernaryVolume or TernaryGrid): segments (without superquadrics),
    contours, NBV scoring; `kwargs` go to `plan_object_views`. up: the world's up (table_z is the table's
    height along it); default the volume's, else z."""
    t0 = time.perf_counter()
    opts = segment_options or SegmentOptions(superquadrics=False)
    if up is None:
        up = getattr(volume, "up", None)
    elif isinstance(opts.segmentation.up, str):  # "auto": the caller's up, not the volume's
        opts = replace(opts, segmentation=replace(opts.segmentation, up=tuple(float(v) for v in up)))
    segments = analyse_volume(volume, opts)
    t_seg = time.perf_counter() - t0
    t = time.perf_counter()
    weights = _weights(volume, weights)
    contours, _ = volume_contours(volume, w_th, weights)
    t_cont = time.perf_counter() - t
    if scorer is None:
        scorer = nbv_scorer(known_grid(volume, w_th, weights)[0], camera, table_z=table_z, up=up)
    plan = plan_object_views(segments, contours, scorer, score_threshold=score_threshold, up=up, **kwargs)
    plan.timing.update({"segmentation": t_seg, "contours": t_cont, "total": time.perf_counter() - t0})
    return plan
