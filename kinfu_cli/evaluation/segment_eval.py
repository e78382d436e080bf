"""`kinfu eval segment`: a segmentation's files against a labels file, and the threshold sweep.

The predicted segments are what `kinfu segment` wrote: its folder (segments.ply, segments.json) or any
labelled cloud (`io.labelled_cloud`). segments.ply carries the segment as a colour (support plane grey,
dropped points black, one colour per segment); the colour groups are checked against segments.json's
point counts. Ground-truth labels are moved onto the segmented points by nearest neighbour within
`max_distance` (kd-tree); segmented points with no ground-truth point that close are left out and
counted, as are ground-truth points no segmented point came near (surface the cameras never saw).
Scores: `evaluation.segments` (boundary P/R at T_eval on the T_eval neighbourhood graph, BCE, object
recall, over-/under-segmentation).

`sweep_segmentation` is the thesis' PR-curve experiment on generated scenes: fuse each
`sim.scene.segmentation_scene` once, then segment its surface over a range of one segmentation
threshold and score every run against the scene's labelled surface.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, KinfuError
from kinfu_cli.core.grid import check_up
from kinfu_cli.core.neighbours import transfer_nearest
from kinfu_cli.core.progress import progress
from kinfu_cli.io.labelled_cloud import (LabelledCloud, LabelsFileError, ply_points, read_labelled_cloud,
                                         read_ply_vertices)
from kinfu_cli.evaluation.segments import MATCHINGS, consistency_errors, score_segmentation

PLANE_GREY = 153  # segments.ply: the support plane's colour (0.6 as uint8); dropped points are black
SWEEP_DEFAULT = ("concavity_tolerance_deg", (0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0))
# values swept by default per parameter, in SegmentationParams.color_distance (chromaticity by default: at most
# sqrt(2); the thesis' RGB at most sqrt(3)): a T_lccp of 2 prunes nothing, the unpruned LCCP. The t_lccp values span
# the chroma curve on tuning seeds 0, 1, 8-139 (0.02: object recall ~0.88, 0.25: as unpruned)
SWEEP_VALUES = {"t_lccp": (0.02, 0.04, 0.08, 0.12, 0.16, 0.25, 2.0), "t_ff": (0.1, 0.2, 0.3, 0.5, 0.7, 1.0)}
# t_lccp in the thesis' RGB distance (the chroma values would all cut objects into faces there)
RGB_T_LCCP_VALUES = (0.1, 0.15, 0.2, 0.3, 0.4, 0.6, 2.0)


@dataclass
class PredictedSegments:
    """A segmentation's points and labels (0 support plane, 1.. segments, -1 dropped), the up direction
    the segmentation used (None when unknown), where the labels came from, and anything doubtful."""

    points: np.ndarray
    labels: np.ndarray
    up: np.ndarray | None
    source: str
    warnings: list[str] = field(default_factory=list)


def _labels_from_colours(path: Path) -> tuple[np.ndarray, np.ndarray]:
    vertex = read_ply_vertices(path)
    names = vertex.dtype.names or ()
    if not {"red", "green", "blue"} <= set(names):
        raise LabelsFileError(f"{path}: neither a per-point 'label' nor segment colours (expected kinfu segment's "
                              f"segments.ply or a labels file)")
    rgb = np.stack([vertex["red"], vertex["green"], vertex["blue"]], axis=1)
    rgb = np.round(rgb * 255).astype(np.int64) if rgb.dtype.kind == "f" else rgb.astype(np.int64)
    code = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    uniq, first, inv = np.unique(code, return_index=True, return_inverse=True)
    ids = np.empty(len(uniq), dtype=np.int64)
    ids[np.argsort(first)] = np.arange(1, len(uniq) + 1)  # segments numbered in order of first appearance
    ids[uniq == (PLANE_GREY << 16 | PLANE_GREY << 8 | PLANE_GREY)] = 0
    ids[uniq == 0] = -1
    return ply_points(vertex, path), ids[inv.ravel()]


def load_predicted_segments(path: str | os.PathLike) -> PredictedSegments:
    """A `kinfu segment` folder, its segments.ply (or segments.json, which names the same result), or a labels
    file (.ply with `label`, .npz)."""
    path = Path(path)
    if path.name == "segments.json" and (path.parent / "segments.ply").is_file():
        path = path.parent / "segments.ply"  # the JSON holds no points: score the cloud written beside it
    if path.is_dir():
        ply = path / "segments.ply"
        if not ply.is_file():
            raise LabelsFileError(f"{path}: no segments.ply (expected a kinfu segment output folder)")
        path = ply
    if not path.is_file():
        raise LabelsFileError(f"{path}: no such segments file or folder")
    warnings: list[str] = []
    try:
        cloud = read_labelled_cloud(path)
        points, labels, source = cloud.points, cloud.labels, "label property"
    except LabelsFileError as e:
        if "no per-point 'label'" not in str(e):
            raise
        points, labels = _labels_from_colours(path)
        source = "segment colours"
    up = None
    meta = path.parent / "segments.json"
    if path.name == "segments.ply" and meta.is_file():
        try:
            doc = json.loads(meta.read_text())
        except (OSError, ValueError, RecursionError) as e:
            raise LabelsFileError(f"{meta}: not readable JSON ({type(e).__name__}: {e})") from None
        if not isinstance(doc, dict):
            raise LabelsFileError(f"{meta}: expected the JSON object `kinfu segment` writes")
        if doc.get("up") is not None:
            try:
                up = check_up(doc["up"])
            except ConfigError:
                raise LabelsFileError(f"{meta}: 'up' is {doc['up']!r}, expected a finite non-zero direction") from None
        if source == "segment colours":
            try:
                want = sorted(int(s["point_count"]) for s in doc.get("segments", [])
                              if s.get("kind") in ("object", "background"))  # both have a colour in segments.ply
            except (KeyError, TypeError, ValueError, AttributeError):
                raise LabelsFileError(f"{meta}: 'segments' is not a list of segments with integer point counts") \
                    from None
            have = sorted(int(n) for n in np.bincount(labels[labels > 0])[1:] if n > 0)
            if want != have:
                warnings.append(f"{path}: its {len(have)} segment colours do not match the {len(want)} segments "
                                f"of {meta} (point counts differ): two segments may share a colour")
    return PredictedSegments(points, labels, up, source, warnings)


def load_ground_truth_labels(path: str | os.PathLike) -> LabelledCloud:
    """A labels file, or a folder holding labels.ply or labels.npz (a `kinfu synth` ground_truth/ or its parent;
    the per-point labels.ply first, the room scene has only the per-voxel labels.npz)."""
    path = Path(path)
    if path.is_dir():
        for cand in (path / name for name in ("labels.ply", "labels.npz")):
            for c in (cand, cand.parent / "ground_truth" / cand.name):
                if c.is_file():
                    return read_labelled_cloud(c)
        raise LabelsFileError(f"{path}: no labels.ply or labels.npz here nor in ground_truth/ (kinfu synth writes "
                              f"them; or give a labels file)")
    return read_labelled_cloud(path)


def label_names(labels_path: str | os.PathLike | None) -> dict[int, str]:
    """Object names by label from the changes.json beside a kinfu synth labels.ply / labels.npz ({} when none)."""
    if labels_path is None:
        return {}
    meta = Path(labels_path).parent / "changes.json"
    try:
        doc = json.loads(meta.read_text())
        names = {int(k): str(v) for k, v in doc.get("labels", {}).items()}  # the room scene names its labels
        return ({0: "table"} | names | {int(o["label"]): str(o["id"]) for o in doc.get("objects", [])
                                         if o.get("present_after")})
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError):  # names are optional
        return {}


def transfer_labels(src_points: np.ndarray, src_labels: np.ndarray, dst_points: np.ndarray,
                    max_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Label of the nearest source point for each destination point (-1 when none within max_distance),
    and that distance (inf when none)."""
    out = np.full(len(dst_points), -1, dtype=np.int64)
    return out, transfer_nearest(src_points, src_labels, dst_points, max_distance, out)


@dataclass
class SegmentEvalResult:
    """The results document (JSON-ready) and the evaluated points for plots."""

    document: dict
    points: np.ndarray  # evaluated segmented points
    labels: np.ndarray
    gt_labels: np.ndarray
    point_errors: np.ndarray  # per-point consistency error max(E(S,G,p), E(G,S,p))
    up: np.ndarray | None


def check_eval_numbers(t_eval: float, max_distance: float, cover: float, share: float,
                       matching: str = "assignment") -> None:
    """The scoring numbers checked before anything is read (ConfigError naming the first bad one)."""
    if matching not in MATCHINGS:
        raise ConfigError(f"expected one of {', '.join(MATCHINGS)}, got {matching!r}", parameter="matching")
    for name, v, lo, hi in (("t_eval", t_eval, 0, 1), ("max_distance", max_distance, 0, 1), ("cover", cover, 0, 1),
                            ("share", share, 0, 0.5)):
        if not (lo < v <= hi):
            raise ConfigError(f"expected a number in ({lo}, {hi}], got {v}", parameter=name)


def score_labelled_points(points: np.ndarray, labels: np.ndarray, gt: LabelledCloud, *, t_eval: float = 0.02,
                          max_distance: float = 0.015, cover: float = 0.8, share: float = 0.2,
                          min_object_points: int = 20, matching: str = "assignment"
                          ) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray]:
    """Scores of one labelling of `points` against the ground-truth cloud: (document, kept mask,
    transferred ground-truth labels of the kept points, per-point consistency error)."""
    gt_lab, _ = transfer_labels(gt.points, gt.labels, points, max_distance)
    keep = gt_lab >= 0
    n_keep = int(keep.sum())
    if n_keep == 0:
        raise KinfuError(f"no segmented point lies within {max_distance} m of a ground-truth point: are both clouds "
                         f"in the same world frame?", parameter="max_distance")
    pts, lab, g = points[keep], labels[keep], gt_lab[keep]
    sc = score_segmentation(pts, lab, g, t_eval=t_eval, cover=cover, min_object_points=min_object_points,
                            share=share, matching=matching)
    # ground truth no segmented point came near: never seen, so not held against the segmentation
    near, _ = transfer_labels(points, np.zeros(len(points), dtype=np.int64), gt.points, max_distance)
    unseen = near < 0
    labelled = gt.labels >= 0
    doc = {"boundary_precision": sc.boundary_precision, "boundary_recall": sc.boundary_recall,
           "boundary_f": (2 * sc.boundary_precision * sc.boundary_recall
                          / max(sc.boundary_precision + sc.boundary_recall, 1e-12)),
           "bce": sc.bce, "object_recall": sc.object_recall, "objects_found": sc.objects_found,
           "objects_total": sc.objects_total, "over_segmented": sc.over_segmented,
           "under_segmenting": sc.under_segmenting, "segments": sc.segments,
           "boundary_points": {"predicted": sc.boundary_pred, "ground_truth": sc.boundary_gt},
           "points": {"segmented": int(len(points)), "evaluated": n_keep, "unmatched": int(len(points) - n_keep),
                      "unmatched_share": float(1 - n_keep / len(points)), "dropped_by_segmentation": int(np.sum(lab < 0)),
                      "ground_truth": int(labelled.sum()), "ground_truth_unseen": int(np.sum(unseen & labelled)),
                      "ground_truth_unseen_share": float(np.sum(unseen & labelled) / max(labelled.sum(), 1))},
           "per_object": sc.per_object, "over": sc.details["over"], "under": sc.details["under"]}
    return doc, keep, g, consistency_errors(lab, g)


def evaluate_segments(segments: str | os.PathLike | PredictedSegments, ground_truth: str | os.PathLike | LabelledCloud,
                      *, t_eval: float = 0.02, max_distance: float = 0.015, cover: float = 0.8, share: float = 0.2,
                      min_object_points: int = 20, matching: str = "assignment") -> SegmentEvalResult:
    """Score a segmentation (files or loaded) against ground-truth labels; see the module docstring."""
    check_eval_numbers(t_eval, max_distance, cover, share, matching)
    pred = segments if isinstance(segments, PredictedSegments) else load_predicted_segments(segments)
    gt = ground_truth if isinstance(ground_truth, LabelledCloud) else load_ground_truth_labels(ground_truth)
    doc, keep, g, err = score_labelled_points(pred.points, pred.labels, gt, t_eval=t_eval, max_distance=max_distance,
                                              cover=cover, share=share, min_object_points=min_object_points,
                                              matching=matching)
    warnings = list(pred.warnings)
    p = doc["points"]
    if p["unmatched_share"] > 0.1:
        warnings.append(f"{p['unmatched']} of {p['segmented']} segmented points ({p['unmatched_share']:.0%}) have no "
                        f"ground-truth point within {max_distance} m and are not scored")
    document = {"input": {"segments": str(segments) if not isinstance(segments, PredictedSegments) else None,
                          "ground_truth": str(gt.path) if gt.path else None, "labels_from": pred.source},
                "t_eval": t_eval, "matching": matching, "max_distance": max_distance, "cover": cover, "share": share,
                "min_object_points": min_object_points, **doc, "warnings": warnings}
    names = label_names(gt.path)
    for o in document["per_object"]:
        o["name"] = names.get(o["object"], str(o["object"]))
    return SegmentEvalResult(document, pred.points[keep], pred.labels[keep], g, err, pred.up)


# ---- the sweep ---------------------------------------------------------------------------------------------

def _sweep_fields() -> dict[str, type]:
    from kinfu_cli.segmentation.segments import SegmentationParams

    out = {f.name: f.type for f in fields(SegmentationParams)
           if isinstance(getattr(SegmentationParams(), f.name), (int, float))
           and not isinstance(getattr(SegmentationParams(), f.name), bool)}
    return out | {"t_lccp": float}  # off (None) by default, a number when swept


def sweep_method(parameter: str, method: str | None = None) -> str:
    """The segmentation method a sweep runs: given, or the one the parameter belongs to (T_ff: Flood Fill)."""
    return method or ("flood-fill" if parameter == "t_ff" else "lccp")


def default_sweep_values(parameter: str, color_distance: str = "chroma") -> tuple[float, ...]:
    """The values swept when none are given (t_lccp's depend on the colour distance)."""
    if parameter == "t_lccp" and color_distance == "rgb":
        return RGB_T_LCCP_VALUES
    return SWEEP_VALUES.get(parameter, SWEEP_DEFAULT[1])


# The generated scenes: each layout's fusion cube (m); the voxel is 1.1 m / `resolution` in both
SCENE_SIZES = {"objects": 1.1, "tabletop": 1.6}


def fuse_segmentation_scene(seed: int, *, resolution: int = 160, size: float = 1.1, width: int = 240,
                            height: int = 180, frames: int = 24, layout: str = "objects", colors=("none",),
                            photometric: bool | dict = False):
    """The volumes of the generated scene `seed` (the after state of kinfu synth's `layout` scene, fused from every
    camera pose with the sensor noise), one per colour mode in `colors`, and that scene."""
    from kinfu_cli.evaluation.segments import fuse_synthetic_volumes

    return fuse_synthetic_volumes(seed, colors=colors, resolution=resolution, size=size, width=width, height=height,
                                  frames=frames, layout=layout, photometric=photometric)


def _sweep_options(parameter: str, values: list[float], method: str, color: bool, as_int: bool,
                   color_distance: str) -> list:
    from kinfu_cli.segmentation.pipeline import SegmentOptions

    base = SegmentOptions(superquadrics=False, color=color)
    out = []
    for v in values:
        if not np.isfinite(v):
            raise ConfigError(f"expected finite values of {parameter}, got {v}", parameter="sweep_values")
        seg = replace(base.segmentation, **{parameter: int(round(v)) if as_int else v}, method=method,
                      up=(0.0, 0.0, 1.0), color_distance=color_distance)
        opts = replace(base, segmentation=seg)
        try:
            opts.validate()
        except ConfigError as exc:  # the value is the sweep's, not an option the user set
            raise ConfigError(f"{v} as {parameter}: {exc.detail}", parameter="sweep_values") from None
        out.append(opts)
    return out


def _check_sweep_inputs(parameter: str, values, seeds, layouts, colors) -> tuple[list, list, list, list]:
    from kinfu_cli.evaluation.segments import COLOR_CHOICES

    numeric = _sweep_fields()
    if parameter not in numeric:
        raise ConfigError(f"expected a numeric segmentation parameter ({', '.join(sorted(numeric))}), got "
                          f"{parameter!r}", parameter="sweep_parameter")
    values = [float(v) for v in values]
    if not values:
        raise ConfigError("expected at least one value", parameter="sweep_values")
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ConfigError("expected at least one scene seed", parameter="scenes")
    for s in seeds:  # numpy refuses negative seeds with a bare ValueError
        check_number(s, "scenes", 0, 2 ** 63 - 1, integer=True)
    layouts = list(dict.fromkeys(layouts))
    if not layouts or any(lay not in SCENE_SIZES for lay in layouts):
        raise ConfigError(f"expected scene layouts among {', '.join(SCENE_SIZES)}, got {layouts}", parameter="layouts")
    colors = list(dict.fromkeys(colors))
    if not colors or any(c not in COLOR_CHOICES for c in colors):
        raise ConfigError(f"expected colour modes among {', '.join(COLOR_CHOICES)}, got {colors}", parameter="color")
    return values, seeds, layouts, colors


ROW_KEYS = ("boundary_precision", "boundary_recall", "boundary_f", "bce", "object_recall", "objects_found",
            "objects_total", "over_segmented", "under_segmenting", "segments")


def sweep_segmentation(seeds=(0, 1, 2), parameter: str = SWEEP_DEFAULT[0], values=None, *,
                       method: str | None = None, colors=("mean", "mode"), layouts=("objects",), photometric: bool = True,
                       t_eval: float = 0.02, max_distance: float = 0.015, cover: float = 0.8, share: float = 0.2,
                       resolution: int = 160, size: float | None = None, frames: int = 24,
                       quiet: bool = True, matching: str = "assignment", color_distance: str = "chroma") -> dict:
    """Boundary P/R, BCE, object recall of the segmentation of generated scenes over `values` of one
    segmentation parameter (a numeric field of SegmentationParams; t_lccp and t_ff as in thesis Figs.
    4.10-4.11), for every scene layout x seed x colour mode ("none", "mean", "mode": the volume fused without
    colour, with the running mean, with the mode filter; photometric: the simulator's colour effects on).
    size: the fusion cube (default SCENE_SIZES per layout; the voxel stays 1.1 m / resolution).
    color_distance: of t_lccp / t_ff (SegmentationParams.color_distance). Returns the JSON-ready document."""
    from kinfu_cli.segmentation.pipeline import analyse_cloud
    from kinfu_cli.segmentation.surface import surface_from_volume
    from kinfu_cli.sim.scene import scene_label_cloud

    values = default_sweep_values(parameter, color_distance) if values is None else values
    values, seeds, layouts, colors = _check_sweep_inputs(parameter, values, seeds, layouts, colors)
    check_eval_numbers(t_eval, max_distance, cover, share, matching)
    method = sweep_method(parameter, method)
    as_int = _sweep_fields()[parameter] in (int, "int")
    opts = {c: _sweep_options(parameter, values, method, c != "none", as_int, color_distance) for c in colors}
    scenes = []
    steps = [(lay, s, c, k) for lay in layouts for s in seeds for c in [None, *colors]
             for k in ([0] if c is None else range(len(values)))]
    vols = gt = objects = None
    clouds: dict = {}
    for lay, seed, c, k in progress(steps, total=len(steps), desc="sweep", quiet=quiet):
        if c is None:  # a new scene: fuse it once per colour mode from the same images
            cube = size or SCENE_SIZES[lay]
            res_l = max(16, int(round(resolution * cube / 1.1))) if size is None else resolution
            vols, scene = fuse_segmentation_scene(seed, resolution=res_l, size=cube, frames=frames, layout=lay,
                                                  colors=colors, photometric=photometric)
            clouds = {m: surface_from_volume(v, min_weight=opts[m][0].min_weight, resolution=opts[m][0].resolution)
                      for m, v in vols.items()}
            pts, lab = scene_label_cloud(scene)
            gt = LabelledCloud(pts, lab)
            objects = {str(scene.label_of(o.id)): o.id for o in scene.present_objects}
            continue
        if k == 0:
            scenes.append({"layout": lay, "seed": seed, "color": c, "points": int(len(clouds[c].points)),
                           "rows": [], "objects": objects})
        cloud = clouds[c]
        res = analyse_cloud(cloud.points, cloud.normals, opts[c][k], up_source="option", colors=cloud.colors)
        doc, *_ = score_labelled_points(res.segmentation.points, res.segmentation.labels, gt, t_eval=t_eval,
                                        max_distance=max_distance, cover=cover, share=share, matching=matching)
        scenes[-1]["rows"].append({"value": values[k], **{key: doc[key] for key in ROW_KEYS},
                                   "unmatched_share": doc["points"]["unmatched_share"],
                                   "missed": [objects.get(str(o["object"]), o["object"]) for o in doc["per_object"]
                                              if not o["found"]]})
    for s in scenes:
        s["min_bce"] = min(r["bce"] for r in s["rows"])
        best = max(s["rows"], key=lambda r: r["boundary_f"])
        s["best_f"] = {"value": best["value"], "boundary_f": best["boundary_f"]}
    means = {}
    for c in colors:
        group = [s for s in scenes if s["color"] == c]
        means[c] = {key: [float(np.mean([s["rows"][i][key] for s in group])) for i in range(len(values))]
                    for key in ("boundary_precision", "boundary_recall", "boundary_f", "bce", "object_recall")}
    return {"parameter": parameter, "method": method, "values": values, "seeds": seeds, "layouts": layouts,
            "colors": colors, "photometric": photometric, "t_eval": t_eval, "matching": matching,
            "color_distance": color_distance,
            "max_distance": max_distance,
            "cover": cover, "share": share,
            "fusion": {"resolution": resolution, "voxel_m": (size or 1.1) / resolution, "frames": frames,
                       "sizes": {lay: size or SCENE_SIZES[lay] for lay in layouts}},
            "scenes": scenes, "means": means}
