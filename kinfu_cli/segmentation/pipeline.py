"""`kinfu segment` as one library call: volume -> surface cloud -> segments -> saliency -> superquadrics.

`segment_volume(volume_or_path, options)` is the driver; it returns a `SegmentResult` whose `to_json()`
is segments.json. `analyse_volume` / `analyse_cloud` are its steps for callers that already hold a
volume or a cloud. Files are written by `segmentation.outputs.write_segment_outputs`.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.grid import TernaryGrid, check_up, read_ternary
from kinfu_cli.core.point_pairs import check_pair_count
from kinfu_cli.fusion.extent import CUT_LINE_M, CUT_MIN_VOXELS, FACES
from kinfu_cli.fusion.volume import TernaryVolume, load_volume
from kinfu_cli.segmentation.multi_superquadric import MultiSuperquadric, fit_multi_superquadric
from kinfu_cli.segmentation.background import background_segments
from kinfu_cli.segmentation.saliency import ISOLATION_HINT, SegmentSaliency, oriented_box, segment_saliency
from kinfu_cli.segmentation.shape_prior import classify_shape, exponent_bounds
from kinfu_cli.segmentation.bridges import volume_space
from kinfu_cli.segmentation.segments import MAX_DISTANCE_M, PLANE_LABEL, Segmentation, SegmentationParams, segment_cloud
from kinfu_cli.segmentation.superquadric import OVERSIZE_FACTOR, SegmentError, SuperquadricFit, fit_superquadric, \
    oversize
from kinfu_cli.segmentation.surface import SurfaceCloud, surface_from_volume

# in a room (segments: structure) label 0 is floor and walls: the support entry's box and centroid are taken over
# its points this close to the support plane (m; a far floor's band reaches 6 cm), the rest counted as structure
ROOM_SUPPORT_SLAB = 0.1
SUPPORT_VS_UP_DEG = 45.0  # without an up, a support plane this far from the volume's own up is said to be doubtful
FLOOR_FACE_DEG = 45.0  # the grid face whose outward normal lies this close to "down" is the support's: not a cut


@dataclass
class SegmentOptions:
    """Every knob of `segment_volume`; the field names are the parameter names errors report."""

    resolution: float = 0.01  # surface cloud thinning (m)
    min_weight: float = 1.0  # TSDF weight for a voxel to count as observed
    isolation_threshold: float = 0.02  # B_th (m), eq. 3.11
    superquadrics: bool = True
    sq_max_points: int = 200
    sq_exponent_bounds: tuple[float, float] = (0.1, 1.9)
    sq_cost: str = "volume"
    sq_min_points: int = 30
    shape_prior: bool = True  # thesis 7.3: classify each segment, fit inside its class's eq. 7.11 exponent bounds
    multi_sq: bool = False  # thesis ch. 8 split for segments whose single fit is poor
    msq_trigger: float = 0.005  # single-superquadric RMS residual (m) above which the split is tried
    msq_height: int = 3
    msq_mu: float = 0.03
    msq_cut: str = "volume"  # Alg. 4's root cut: "volume" (ours) or the thesis' "barycentre"
    color: bool = True  # use the volume's per-voxel colour (when it was fused with colour) in segmentation
    segmentation: SegmentationParams = field(default_factory=SegmentationParams)
    # the volume-dependent segmentation defaults follow a coarse volume's voxel (`scale_for_voxel`); the names in
    # `explicit` are the caller's choices and never scaled (kinfu segment: the options given on the command line)
    scale_to_voxel: bool = True
    explicit: tuple[str, ...] = ()

    def validate(self) -> None:
        """ConfigError naming the first option out of its range, before any work is done."""
        # a spacing below 0.1 mm thins nothing (open3d refuses it outright): refused rather than used silently
        check_number(self.resolution, "resolution", 1e-4, 1, unit="m")
        check_number(self.min_weight, "min_weight", 0, 255)
        if not 0 <= self.msq_height <= 6:
            raise ConfigError(f"expected 0..6, got {self.msq_height}", parameter="msq_height")
        check_number(self.msq_mu, "msq_mu", 0, 10, low_open=True, unit="m")
        check_number(self.msq_trigger, "msq_trigger", 0, 10, unit="m")
        if self.sq_max_points < 10:
            raise ConfigError(f"must be >= 10, got {self.sq_max_points}", parameter="sq_max_points")
        self.segmentation.validate()
        check_number(self.isolation_threshold, "isolation_threshold", 0, 10, low_open=True, unit="m")
        if self.superquadrics:
            lo, hi = self.sq_exponent_bounds
            if not 0.0 < lo < hi <= 2.0:
                raise ConfigError(f"expected 0 < lo < hi <= 2, got {self.sq_exponent_bounds}",
                                  parameter="sq_exponent_bounds")
            if self.sq_cost not in ("radial", "volume"):
                raise ConfigError(f"expected 'radial' or 'volume', got {self.sq_cost!r}", parameter="sq_cost")


def support_plane_points(seg: Segmentation) -> np.ndarray:
    """The support plane's own points: label 0, or in a room (label 0 is floor and walls) those within
    ROOM_SUPPORT_SLAB of the support plane, so that its box and centroid are the floor's."""
    pts = seg.points[seg.labels == PLANE_LABEL]
    if (seg.stats.get("structure") or {}).get("room") and seg.plane is not None:
        pts = pts[np.abs(pts @ seg.plane[:3] + seg.plane[3]) <= ROOM_SUPPORT_SLAB]
    return pts


@dataclass
class SegmentResult:
    """What `segment_volume` found; `to_json()` is the segments.json document."""

    cloud: SurfaceCloud
    segmentation: Segmentation
    saliency: list[SegmentSaliency]  # decreasing saliency, support plane excluded
    superquadrics: dict[int, SuperquadricFit | str]  # fit, or the reason there is none
    timing: dict[str, float]
    options: SegmentOptions
    multi: dict[int, MultiSuperquadric] = field(default_factory=dict)  # with options.multi_sq
    up_source: str = ""  # where the support plane's expected normal came from (see `resolve_up`)
    warnings: list[str] = field(default_factory=list)  # an empty result's structural reason, with counts
    shape_classes: dict[int, ShapeClass] = field(default_factory=dict)  # with options.shape_prior
    grid_faces: dict[int, list[str]] = field(default_factory=dict)  # segment id -> grid faces it touches (a cut)
    # segment id -> why it is background, not an object (background.py: below the support or beyond its extent)
    background: dict[int, str] = field(default_factory=dict)

    @property
    def objects(self) -> list[SegmentSaliency]:
        """The segments that are objects (not background), most salient first."""
        return [s for s in self.saliency if s.id not in self.background]

    def to_json(self) -> dict:
        segs = []
        seg = self.segmentation
        plane_pts = support_plane_points(seg)
        objects = self.objects
        ranks = {s.id: rank for rank, s in enumerate(objects, start=1)}
        for s in objects + [s for s in self.saliency if s.id in self.background]:
            sq = self.superquadrics.get(s.id)
            kind = {"kind": "background", "rank": None, "background_reason": self.background[s.id]} \
                if s.id in self.background else {"kind": "object", "rank": ranks[s.id]}
            segs.append({
                "id": s.id, **kind, "point_count": s.n_points,
                "centroid": s.centroid.tolist(), "oriented_box": s.box.to_json(),
                "bounding_sphere": {"center": s.box.center.tolist(), "radius": s.bounding_radius},
                "isolation": s.isolation, "roundness": s.roundness, "saliency": s.saliency,
                "superquadric": sq_json(sq, s) if isinstance(sq, SuperquadricFit) else None,
                "touches_grid_faces": self.grid_faces.get(s.id, []),
                **({"superquadric_error": sq} if isinstance(sq, str) else {}),
                **(self.shape_classes[s.id].to_json() if s.id in self.shape_classes else {}),
                **({"multi_superquadric": self.multi[s.id].to_json()} if s.id in self.multi else {}),
            })
        structure = seg.stats.get("structure") or {}
        room = ({"structure": {"points": int(np.sum(seg.labels == PLANE_LABEL)), "planes": structure["planes"]}}
                if structure.get("room") else {})
        if len(plane_pts):
            box = oriented_box(plane_pts)
            segs.append({"id": PLANE_LABEL, "kind": "support_plane", "rank": None, "point_count": int(len(plane_pts)),
                         "centroid": plane_pts.mean(axis=0).tolist(), "oriented_box": box.to_json(),
                         "plane": None if seg.plane is None else seg.plane.tolist(),
                         "isolation": None, "roundness": None, "saliency": None, "superquadric": None, **room})
        up = self.options.segmentation.up
        return {"segments": segs, "support_plane": None if seg.plane is None else seg.plane.tolist(),
                "up": None if up is None else [float(v) for v in self.options.segmentation.up_vector()],
                "up_source": self.up_source, "warnings": list(self.warnings),
                "points": int(len(seg.points)), "noise_points": int(np.sum(seg.labels < 0)),
                "stats": seg.stats, "timing_s": self.timing, "options": asdict(self.options)}


def sq_json(fit: SuperquadricFit, s: SegmentSaliency) -> dict:
    """A segment's superquadric entry: the fit, and how its largest side compares with its points' box
    (box_ratio; oversized above OVERSIZE_FACTOR: not a shape of its points)."""
    ratio = oversize(fit.superquadric.size, s.box.extents)
    return {**fit.to_json(), "box_ratio": ratio if np.isfinite(ratio) else None,
            "oversized": bool(ratio > OVERSIZE_FACTOR)}


def oversize_warnings(saliency: list[SegmentSaliency], fits: dict[int, SuperquadricFit | str]) -> list[str]:
    """The segments whose superquadric's largest side exceeds OVERSIZE_FACTOR x their points' box's: a fit that
    looks converged and describes a shape the points do not have (a 0.55 m disc on a 0.19 m plate)."""
    said = []
    for s in sorted(saliency, key=lambda s: s.id):
        fit = fits.get(s.id)
        if isinstance(fit, SuperquadricFit) and (r := oversize(fit.superquadric.size, s.box.extents)) > OVERSIZE_FACTOR:
            said.append(f"{s.id} ({2 * float(np.max(fit.superquadric.size)):.2g} m on a "
                        f"{float(np.max(s.box.extents)):.2g} m box, {r:.1f}x)")
    if not said:
        return []
    return [f"segment{'s' if len(said) > 1 else ''} {', '.join(said)}: the superquadric's largest side exceeds "
            f"{OVERSIZE_FACTOR:g}x the largest side of the points' box: not a shape of its points (flagged "
            f"oversized; kinfu grasp skips such segments)"]


def grid_face_contacts(seg: Segmentation, volume, resolution: float) -> dict[int, list[str]]:
    """Object segment id -> the faces of the volume's grid (fusion.extent FACES) it touches: the grid cuts it
    off there. Touching: as many of its points as a CUT_LINE_M line of surface holds (at least CUT_MIN_VOXELS,
    as fuse counts face contacts) lie within a voxel of the face, plus half the cloud's thinning `resolution`
    (the thinning averages points inwards). The face under the support plane (or the volume's up) is left out:
    objects stand on it."""
    v = float(volume.voxel_size)
    lo = np.asarray(volume.origin, dtype=np.float64)
    hi = lo + np.asarray(volume.shape, dtype=np.float64) * v
    reach = v + resolution / 2
    need = max(CUT_MIN_VOXELS, int(np.ceil(CUT_LINE_M / max(v, resolution))))
    up = seg.plane[:3] if seg.plane is not None else getattr(volume, "up", None)
    objects = seg.labels > 0
    out: dict[int, list[str]] = {}
    for k, face in enumerate(FACES):
        axis, outward = k // 2, 1.0 if k % 2 else -1.0
        if up is not None and -outward * float(up[axis]) / float(np.linalg.norm(up)) > np.cos(
                np.radians(FLOOR_FACE_DEG)):
            continue
        gap = hi[axis] - seg.points[:, axis] if outward > 0 else seg.points[:, axis] - lo[axis]
        ids, counts = np.unique(seg.labels[objects & (gap <= reach)], return_counts=True)
        for sid in ids[counts >= need]:
            out.setdefault(int(sid), []).append(face)
    return out


def grid_face_warnings(faces: dict[int, list[str]]) -> list[str]:
    """The segments the grid cuts off: their box, superquadric and grasp describe only the part inside it."""
    if not faces:
        return []
    if len(faces) == 1:
        ((sid, f),) = faces.items()
        who = f"segment {sid} touches the grid's {', '.join(f)} face{'s' if len(f) > 1 else ''}: the grid cuts it"
    else:
        who = ("segments " + ", ".join(f"{sid} ({', '.join(f)})" for sid, f in sorted(faces.items()))
               + " touch the grid's faces: the grid cuts them")
    return [f"{who} off, so box, superquadric and grasp describe only the part inside (flagged touches_grid_faces); "
            f"fuse again with a grid holding the whole object (a larger size or another origin)"]


PRIOR_RESIDUAL_SLACK = 0.25  # a class fit this much worse (RMS) than the free fit is contradicted by the points


@dataclass
class ShapeClass:
    """The shape prior's verdict on one segment: its class, the class probabilities, the exponent bounds
    the fit used (eq. 7.11, within the sq_exponent_bounds option) and whether the class fit was rejected
    (its RMS residual more than PRIOR_RESIDUAL_SLACK above the free fit's: the free fit is kept)."""

    name: str
    probabilities: dict[str, float]
    exponent_bounds: tuple[tuple[float, float], tuple[float, float]]
    rejected: bool = False

    def to_json(self) -> dict:
        return {"shape_class": self.name, "shape_class_probabilities": self.probabilities,
                "shape_prior_exponent_bounds": [list(b) for b in self.exponent_bounds],
                "shape_prior_rejected": self.rejected}


def prior_bounds(shape_class: str, option_bounds: tuple[float, float]
                 ) -> tuple[tuple[float, float], tuple[float, float]]:
    """Eq. 7.11's bounds of the class, narrowed to the user's (lo, hi); where they do not overlap the user's
    bounds win (the option is the user's explicit choice)."""
    lo, hi = option_bounds
    out = []
    for clo, chi in exponent_bounds(shape_class):
        a, b = max(lo, clo), min(hi, chi)
        out.append((a, b) if b - a > 1e-3 else (lo, hi))
    return tuple(out)  # type: ignore[return-value]


def _fit_one(points: np.ndarray, options: SegmentOptions) -> tuple[SuperquadricFit, ShapeClass | None]:
    """The segment's superquadric: a free fit, then (shape prior on) the class from it and, for a class
    other than generic whose bounds exclude the free exponents, a re-fit inside the class's bounds (kept
    unless it fits clearly worse, see ShapeClass)."""
    kw = {"max_points": options.sq_max_points, "cost": options.sq_cost}
    free = fit_superquadric(points, exponent_bounds=options.sq_exponent_bounds, **kw)
    if not options.shape_prior:
        return free, None
    name, proba = classify_shape(points, free)
    bounds = prior_bounds(name, options.sq_exponent_bounds)
    cls = ShapeClass(name, proba, bounds)
    e = free.superquadric.exponents
    if name == "generic" or all(lo <= v <= hi for v, (lo, hi) in zip(e, bounds)):
        return free, cls  # the free optimum already lies inside the class's bounds
    fit = fit_superquadric(points, exponent_bounds=bounds, **kw)
    if fit.residual > (1 + PRIOR_RESIDUAL_SLACK) * free.residual:
        cls.rejected = True
        return free, cls
    return fit, cls


def _fit_superquadrics(seg: Segmentation, saliency: list[SegmentSaliency], options: SegmentOptions
                       ) -> tuple[dict[int, SuperquadricFit | str], dict[int, ShapeClass]]:
    """A superquadric per segment, or why there is none (too few points, degenerate), and the shape
    prior's class of each fitted segment."""
    fits: dict[int, SuperquadricFit | str] = {}
    classes: dict[int, ShapeClass] = {}
    for s in saliency:
        if s.n_points < options.sq_min_points:
            fits[s.id] = f"{s.n_points} points (< sq_min_points {options.sq_min_points})"
            continue
        try:
            fit, cls = _fit_one(seg.points[seg.labels == s.id], options)
        except SegmentError as exc:
            fits[s.id] = str(exc)
            continue
        fits[s.id] = fit
        if cls is not None:
            classes[s.id] = cls
    return fits, classes


def _fit_multi_superquadrics(seg: Segmentation, fits: dict[int, SuperquadricFit | str], options: SegmentOptions
                             ) -> dict[int, MultiSuperquadric]:
    """Thesis ch. 8 split of the segments whose single superquadric fits worse than msq_trigger."""
    multi = {}
    for sid, fit in fits.items():
        if isinstance(fit, SuperquadricFit) and fit.residual > options.msq_trigger:
            try:
                multi[sid] = fit_multi_superquadric(
                    seg.points[seg.labels == sid], height=options.msq_height, mu=options.msq_mu,
                    min_points=options.sq_min_points, max_points=options.sq_max_points,
                    exponent_bounds=options.sq_exponent_bounds, cost=options.sq_cost, cut=options.msq_cut)
            except SegmentError:
                pass  # no split: the single superquadric stands
    return multi


# The segmentation's volume-dependent defaults were chosen on the objects scenes' 6.9 mm voxels with the surface
# cloud thinned at 1 cm (CLOUD_SPACING). A coarser volume's surface holds about one point per voxel v (marching-cubes
# vertices on the voxel edges), so its neighbouring points lie up to sqrt(3) v apart (a voxel's diagonal) and a
# surface holds (CLOUD_SPACING / v)^2 as many points per area. Tuning seeds 0, 1, 8-19 (objects scenes fused at
# 1.0 / 1.5 / 2.0 cm, mode colour), object recall: defaults 0.982 / 0.857 / 0.000; adjacency_radius
# max(18 mm, k v) with k 1.5 / 2 / 2.5: 0.982 / 0.884 / 0.723, 0.991 / 0.893 / 0.723, 0.991 / 0.893 / 0.741; with
# the point counts scaled too, k = 1.75 / 2: 0.982 / 0.902 / 0.848, 0.991 / 0.902 / 0.839 (k = 2: a margin over
# sqrt(3)); exponent 1.5 or a floor of 20 alike; not scaling fragment_points 0.768 at 2 cm. Left alone (within one
# object of 112 at 2 cm): seed_resolution 3 / 4 v (0.848 / 0.830), foot_height / step_min_height v / 2 / v (0.830),
# plane_distance 0.75 / 1 v (0.848 / 0.848). What stays missed at 1.5-3 cm is objects merged with a neighbour closer
# than ~2 v (2.5 / 3 cm: 0 -> 0.804 / 0.755). Boundary P / R at T_eval 2 cm mean little once the points are ~2 cm apart.
VOXEL_ADJACENCY = 2.0  # adjacency_radius >= this x voxel: the diagonal's sqrt(3) with a margin for TSDF noise
CLOUD_SPACING = 0.01  # the point spacing the point counts (min_segment_points, fragment_points) were chosen at
MIN_SCALED_POINTS = 10  # a segment keeps at least this many points (fragment_points twice this) however coarse
COARSE_VOXEL = 0.02  # coarser voxels are a warning (coarse_voxel_warnings): at 2 cm object recall was still 0.84


def scale_for_voxel(options: SegmentOptions, voxel_size: float) -> tuple[SegmentOptions, dict]:
    """Options whose volume-dependent segmentation defaults follow the voxel (see VOXEL_ADJACENCY), and what was
    changed ({name: value}; {} for voxels up to 7 mm, where every scaled value is its default). A value other than
    its default, or named in options.explicit, is the caller's and kept."""
    if not options.scale_to_voxel:
        return options, {}
    v = float(voxel_size)
    share = (CLOUD_SPACING / max(CLOUD_SPACING, v)) ** 2  # points per area against the tuned cloud's
    default = SegmentationParams()
    if VOXEL_ADJACENCY * v > MAX_DISTANCE_M and "adjacency_radius" not in options.explicit:
        raise VolumeError(f"voxel size {v:g} m is too coarse to segment: neighbouring surface points lie "
                          f"{VOXEL_ADJACENCY:g} voxels ({VOXEL_ADJACENCY * v:g} m) apart, beyond any scene "
                          f"(adjacency radius at most {MAX_DISTANCE_M:g} m)")
    wanted = {"adjacency_radius": max(default.adjacency_radius, VOXEL_ADJACENCY * v),
              "min_segment_points": max(MIN_SCALED_POINTS, round(default.min_segment_points * share)),
              "fragment_points": max(2 * MIN_SCALED_POINTS, round(default.fragment_points * share))}
    params = options.segmentation
    changed = {k: val for k, val in wanted.items()
               if k not in options.explicit and getattr(params, k) == getattr(default, k) and val != getattr(params, k)}
    if not changed:
        return options, {}
    return replace(options, segmentation=replace(params, **changed)), changed


def resolve_up(volume, options: SegmentOptions) -> tuple[SegmentOptions, str]:
    """Options whose segmentation.up is a direction or None (never "auto"), and where it came from:
    "option" (given), "none" (any plane), "volume" (the volume's up: fusion or ternary.npz), or
    "assumed-z" ("auto" on a volume that does not know its up: written before kinfu recorded it, or by
    another tool)."""
    up = options.segmentation.up
    if up is None:
        return options, "none"
    if not isinstance(up, str):
        up = tuple(float(v) for v in check_up(up, "up"))
        return replace(options, segmentation=replace(options.segmentation, up=up)), "option"
    vol_up = getattr(volume, "up", None)
    if vol_up is None:
        return replace(options, segmentation=replace(options.segmentation, up=(0.0, 0.0, 1.0))), "assumed-z"
    up = tuple(float(v) for v in vol_up)
    return replace(options, segmentation=replace(options.segmentation, up=up)), "volume"


def no_object_cause(seg: Segmentation, params: SegmentationParams, facing: str) -> str:
    """Why a support plane left no object, from where the points lie along its normal: many below it (a
    flipped up: objects standing on the table lie under a plane facing down), some above it yet no segment
    (too few or too thin: absorbed or dropped), or none rising past the support's band (nothing stands on it,
    or nothing higher than 2 x plane_distance). In a room the support's segment holds the walls too: only dropped
    points count as rising above it. facing: ' facing up [..] (whose)' or ''."""
    height = seg.points @ seg.plane[:3] + seg.plane[3]
    band = 2 * params.plane_distance  # segments never rising above this belong to the support (segments.py)
    room = bool((seg.stats.get("structure") or {}).get("room"))
    below, above = height < -band, (height > band) & ((seg.labels < 0) | (not room))
    if facing and int(below.sum()) >= params.min_segment_points:
        return (f"{int(below.sum())} points lie up to {float(-height.min()):.2g} m below the plane{facing}: if "
                f"they stand on it, that up direction is wrong (flipped?): give the right up direction")
    if above.any():
        return (f"{int(above.sum())} points rise up to {float(height[above].max()):.2g} m above the plane{facing} but "
                f"form no segment of min_segment_points {params.min_segment_points}: an object that small or thin "
                f"is taken into the support or dropped")
    return (f"no point rises more than {band:g} m (2 x plane_distance) above the plane{facing}: nothing stands "
            f"on it, or nothing higher than that")


def support_plane_warnings(seg: Segmentation, up_source: str, params: SegmentationParams | None = None
                           ) -> list[str]:
    """Why there is no support plane, with the counts of the search; or that the plane took every point and
    why (`no_object_cause`: a flipped up, stored in the volume, did that silently, and so do a bare table and
    objects too small to segment); [] otherwise. params: the segmentation's (its defaults when None)."""
    if len(seg.points) == 0:
        return []
    params = params or SegmentationParams()
    if seg.plane is not None:
        if np.any(seg.labels > 0):
            return []
        up = seg.stats.get("support_plane_search", {}).get("up")
        whose = {"assumed-z": "assumed", "volume": "the volume's", "option": "given"}.get(up_source,
                                                                                          up_source or "given")
        facing = "" if up is None else f" facing up {[round(v, 3) for v in up]} ({whose})"
        held, dropped = int(np.sum(seg.labels == PLANE_LABEL)), int(np.sum(seg.labels < 0))
        share = f"all {held}" if not dropped else f"{held} of {len(seg.labels)}"
        return [f"no objects: the support plane's segment holds {share} surface points"
                + (f" ({dropped} dropped as specks)" if dropped else "") + f"; {no_object_cause(seg, params, facing)}"]
    s = seg.stats.get("support_plane_search", {})
    up = s.get("up")
    params_up = "any direction" if up is None else (
        f"up {[round(v, 3) for v in up]} ("
        + {"assumed-z": "assumed: the volume has no up direction", "volume": "the volume's"}.get(up_source, up_source)
        + ")")
    labels = seg.labels[seg.labels > 0]
    share = np.bincount(labels).max() / len(seg.points) if len(labels) else 0.0
    return [f"no support plane: of {s.get('points', len(seg.points))} surface points "
            f"{s.get('candidate_points', 0)} have a normal near {params_up}, the largest plane among them holds "
            f"{s.get('largest_plane_points', 0)} ({s.get('needed_points', 0)} needed) after "
            f"{s.get('planes_tried', 0)} tries; objects stay joined to what they stand on (the largest "
            f"segment holds {share:.0%} of the points)"]


def color_warnings(seg: Segmentation, options: SegmentOptions) -> list[str]:
    """A colour test asked for on a cloud without colours: Flood Fill then groups by normals alone, and LCCP's
    T_lccp cuts nothing."""
    if seg.colors is not None:
        return []
    why = "colour is off" if not options.color else "the volume has no colour (fused without it)"
    params = options.segmentation
    if params.method == "flood-fill":
        return [f"flood fill without colour: {why}, so points are grouped by their normals alone"]
    if params.t_lccp is not None:
        return [f"t_lccp {params.t_lccp:g} without colour: {why}, so no edge is cut by colour"]
    return []


def analyse_cloud(points: np.ndarray, normals: np.ndarray, options: SegmentOptions | None = None,
                  timing: dict | None = None, up_source: str = "", colors: np.ndarray | None = None,
                  space=None) -> SegmentResult:
    """Segment a surface cloud (colours (N, 3) RGB in [0, 1] or None), score saliency, fit superquadrics.
    up_source: where options.segmentation.up came from (`resolve_up`; for the result and its warnings)."""
    options = options or SegmentOptions()
    up = options.segmentation.up
    up_source = up_source or ("none" if up is None else "assumed-z" if isinstance(up, str) else "option")
    timing = dict(timing or {})
    t = time.perf_counter()
    # saliency's pair search within isolation_threshold runs last: a radius spanning the cloud is refused now,
    # not after the segmentation's seconds (the same estimate, on the same points and tree)
    tree = cKDTree(np.asarray(points, dtype=np.float64))
    check_pair_count(tree, options.isolation_threshold, what="surface points", parameter="isolation_threshold",
                     hint=ISOLATION_HINT)
    seg = segment_cloud(points, normals, options.segmentation, colors if options.color else None, space)
    background = background_segments(seg, options.segmentation, space)
    seg.stats["background_segments"] = {reason: sum(r == reason for r in background.values())
                                        for reason in sorted(set(background.values()))}
    timing["segmentation"] = time.perf_counter() - t
    t = time.perf_counter()
    sal = segment_saliency(seg.points, seg.labels, b_th=options.isolation_threshold, exclude=(-1, PLANE_LABEL),
                           tree=tree)
    timing["saliency"] = time.perf_counter() - t
    t = time.perf_counter()
    fits, classes = _fit_superquadrics(seg, sal, options) if options.superquadrics else ({}, {})
    timing["superquadrics"] = time.perf_counter() - t
    multi = {}
    if options.superquadrics and options.multi_sq:
        t = time.perf_counter()
        multi = _fit_multi_superquadrics(seg, fits, options)
        timing["multi_superquadrics"] = time.perf_counter() - t
    return SegmentResult(SurfaceCloud(seg.points, seg.normals, seg.colors), seg, sal, fits, timing, options, multi,
                         up_source, support_plane_warnings(seg, up_source, options.segmentation)
                         + color_warnings(seg, options) + oversize_warnings(sal, fits), classes,
                         background=background)


def analyse_volume(volume: TernaryVolume | TernaryGrid, options: SegmentOptions | None = None) -> SegmentResult:
    """From a fusion TernaryVolume (TSDF surface) or a TernaryGrid (labels only); segmentation.up "auto"
    becomes the volume's up (`resolve_up`), and the volume-dependent defaults follow its voxel (`scale_for_voxel`)."""
    options, up_source = resolve_up(volume, options or SegmentOptions())
    options, scaled = scale_for_voxel(options, volume.voxel_size)
    t = time.perf_counter()
    cloud = surface_from_volume(volume, min_weight=options.min_weight, resolution=options.resolution)
    t_surface = time.perf_counter() - t
    if len(cloud) < options.segmentation.min_segment_points:
        raise VolumeError(f"volume surface has only {len(cloud)} points: nothing to segment")
    space = volume_space(volume)  # bridges across unknown space and background.py read it
    result = analyse_cloud(cloud.points, cloud.normals, options, {"surface": t_surface}, up_source, cloud.colors,
                           space)
    result.segmentation.stats["scaled_for_voxel"] = {"voxel_size": float(volume.voxel_size), **scaled}
    result.grid_faces = grid_face_contacts(result.segmentation, volume, options.resolution)
    result.warnings += grid_face_warnings(result.grid_faces)
    result.warnings += support_against_volume_up(result.segmentation, up_source, getattr(volume, "up", None),
                                                 getattr(volume, "up_source", ""))
    result.warnings += given_up_against_volume_up(options.segmentation.up, up_source, getattr(volume, "up", None),
                                                  getattr(volume, "up_source", ""))
    result.warnings += coarse_voxel_warnings(float(volume.voxel_size))
    return result


def coarse_voxel_warnings(voxel_size: float) -> list[str]:
    """Voxels coarser than COARSE_VOXEL: scaling the defaults (scale_for_voxel) cannot help objects only a few
    voxels across, which merge with their neighbours or vanish (objects scenes at 2.5 / 3 cm: object recall
    0.80 / 0.76; the sample tabletop at 5 cm: 2 of its 4 objects), and nothing else would say so."""
    if voxel_size <= COARSE_VOXEL:
        return []
    return [f"the volume's voxels ({1000 * voxel_size:.0f} mm) are coarser than {1000 * COARSE_VOXEL:.0f} mm: "
            f"objects under about {5 * 100 * voxel_size:.0f} cm (5 voxels) merge with their neighbours or are lost; "
            f"fuse at 1 cm or finer to segment tabletop objects"]


def support_against_volume_up(seg: Segmentation, up_source: str, volume_up, volume_up_source: str) -> list[str]:
    """Without an up (up None) the support is the largest plane's; when the volume knows its up and that plane
    stands more than SUPPORT_VS_UP_DEG from it, the support is likely a wall or a box face: said, not changed."""
    if up_source != "none" or volume_up is None or seg.plane is None:
        return []
    up = np.asarray(volume_up, dtype=np.float64)
    angle = float(np.degrees(np.arccos(np.clip(seg.plane[:3] @ up / np.linalg.norm(up), -1.0, 1.0))))
    if angle <= SUPPORT_VS_UP_DEG:
        return []
    return [f"support plane {angle:.0f} deg from the volume's up {np.round(up, 3).tolist()} "
            f"({volume_up_source or 'recorded'}): without an up the largest plane was taken, likely a wall or a box "
            f"face, not the table; segment with the volume's up (the default) to use it"]


def given_up_against_volume_up(up, up_source: str, volume_up, volume_up_source: str) -> list[str]:
    """An up given by the caller more than SUPPORT_VS_UP_DEG from the one the volume knows (a y-up habit on a
    z-up world): the support is then searched among the walls. Said, not changed: the caller may know better."""
    if up_source != "option" or volume_up is None or up is None or isinstance(up, str):
        return []
    a, b = np.asarray(up, dtype=np.float64), np.asarray(volume_up, dtype=np.float64)
    angle = float(np.degrees(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)), -1.0, 1.0))))
    if angle <= SUPPORT_VS_UP_DEG:
        return []
    return [f"the given up {np.round(a / np.linalg.norm(a), 3).tolist()} is {angle:.0f} deg from the volume's up "
            f"{np.round(b / np.linalg.norm(b), 3).tolist()} ({volume_up_source or 'recorded'}): the support plane was "
            f"searched among planes facing the given up; segment with the volume's up (the default) unless it is wrong"]


def load_segment_input(path: str | os.PathLike) -> TernaryVolume | TernaryGrid:
    """A fusion volume.npz (TSDF + weights) or a ternary.npz (labels only)."""
    path = Path(path)
    if not path.exists():
        raise VolumeError(f"{path}: no such volume file")
    grid = read_ternary(path)
    return grid if grid is not None else load_volume(path, hypotheses=False)  # the winning colours suffice


def segment_volume(volume: str | os.PathLike | TernaryVolume | TernaryGrid,
                   options: SegmentOptions | None = None) -> SegmentResult:
    """The `kinfu segment` pipeline: check the options, load the volume when given a path, then
    surface, segments, saliency and superquadrics. timing["total"] covers all of it."""
    t0 = time.perf_counter()
    options = options or SegmentOptions()
    options.validate()
    path = None
    if isinstance(volume, (str, os.PathLike)):
        path, volume = str(volume), load_segment_input(volume)
    try:
        result = analyse_volume(volume, options)
    except VolumeError as exc:  # what is wrong with the volume (too coarse, no surface) names its file
        if path is None or str(exc).startswith(path):
            raise
        raise VolumeError(f"{path}: {exc}", parameter=exc.parameter) from None
    result.timing["total"] = time.perf_counter() - t0
    return result
