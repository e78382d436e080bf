"""`kinfu grasp` as one library call: segments.json -> a grasp per object segment (thesis ch. 7.2, 7.4, 8.2).

For every object segment with a superquadric (or the parts of its multi-superquadric model), every hand
asked for and every part p as the target (the other parts are obstacles), `solve.grasp_part` finds a pose;
the candidate kept is the converged one with the lowest score (eqs. 7.12, 8.7, 8.12-8.13):

    score = overlap_rms + reach_weight * reach + obstacle_weight * (S - 1) / sum_k F_k

overlap_rms (m) is the F term as a distance (RMS radial distance of H's L points to the target), reach
(m) the palm's distance to the hand's workspace centre: a proxy for the thesis' E_p, E_o, which need the
robot's inverse kinematics (the robot's job, not kinfu's); the last term (eq. 8.11, S parts) keeps a
multi-part grasp away from the other parts. A segment with no converged candidate is reported with
converged = false and no pose. A segment whose superquadric's centre lies outside the oriented box of its points
grown by the superquadric's largest semi-axis is not a fit of them: it is skipped with a warning and listed in
`skipped_segments`; two segments with one id are an error.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, KinfuError
from kinfu_cli.grasp.constraints import Cone, GraspConstraints, Workspace, check_cones, check_workspace, \
    default_workspaces
from kinfu_cli.grasp.hand import HANDS, HandModel
from kinfu_cli.grasp.solve import PartGrasp, grasp_part
from kinfu_cli.segmentation.superquadric import OVERSIZE_FACTOR, Superquadric, oversize


# what a segments.json superquadric may hold (sizes and centre in m)
MAX_SQ_SIZE, MAX_SQ_CENTER, MIN_SQ_EXPONENT, MAX_SQ_EXPONENT = 100.0, 1.0e4, 0.01, 4.0


class GraspError(KinfuError):
    """segments.json cannot be read, or holds nothing to grasp."""


@dataclass
class GraspOptions:
    """Every knob of `plan_grasps`; field names are the parameter names errors report."""

    hand: str = "both"  # right | left | both
    hand_model: HandModel = field(default_factory=HandModel)
    cones: list[Cone] = field(default_factory=list)
    workspaces: dict[str, Workspace] | None = None  # per hand; None: `default_workspaces`
    lifting: bool = True
    pregrasp_distance: float = 0.05  # [code] 0.05 m back along the approach
    reach_weight: float = 0.1
    obstacle_weight: float = 1e-3
    n_starts: int = 4
    max_iter: int = 100
    poor_overlap: float = 0.03  # m: a chosen grasp whose H stays farther (RMS) from the object is flagged
    segment_ids: list[int] | None = None  # only these segment ids

    def hands(self) -> list[str]:
        return list(HANDS) if self.hand == "both" else [self.hand]

    def validate(self) -> None:
        if self.hand not in ("right", "left", "both"):
            raise ConfigError(f"expected right, left or both, got {self.hand!r}", parameter="hand")
        self.hand_model.validate()
        check_cones(self.cones)
        check_number(self.pregrasp_distance, "pregrasp_distance", 0, 1, unit="m")
        check_number(self.reach_weight, "reach_weight", 0, 1e6)
        check_number(self.obstacle_weight, "obstacle_weight", 0, 1e6)
        check_number(self.n_starts, "n_starts", 1, 50, integer=True)
        check_number(self.max_iter, "max_iter", 1, 10000, integer=True)
        check_number(self.poor_overlap, "poor_overlap", 0, 10, low_open=True, unit="m")


@dataclass
class ObjectGrasp:
    """The chosen grasp of one segment and every candidate tried (hand x target part)."""

    segment: int
    parts: list[Superquadric]
    best: PartGrasp | None  # None: no candidate converged
    best_hand: str | None
    best_part: int | None
    candidates: list[tuple[str, int, PartGrasp, float]]  # (hand, part, grasp, score)
    pregrasp_distance: float
    poor_overlap: float
    seconds: float
    cpu_seconds: float
    shape_flags: dict = field(default_factory=dict)  # segment_flags: the segment's grid faces, its fit's convergence

    def to_json(self) -> dict:
        cands = [{"hand": h, "part": p, "converged": g.converged, "score": s if g.converged else None,
                  "cost": g.cost, "overlap_rms_m": g.overlap_rms, "violation": g.violation, "message": g.message,
                  "seconds": g.seconds} for h, p, g, s in self.candidates]
        doc = {"segment": self.segment, "parts": len(self.parts), "converged": self.best is not None,
               "seconds": self.seconds, "cpu_seconds": self.cpu_seconds, "candidates": cands, **self.shape_flags}
        if self.best is None:
            worst = min(self.candidates, key=lambda c: c[2].violation)[2] if self.candidates else None
            doc.update({"hand": None, "pose": None, "pre_grasp": None,
                        "reason": "no candidate satisfied every constraint"
                                  + (f" (least violation {worst.violation:.4g}: {worst.message})" if worst else "")})
            return doc
        g = self.best
        T = g.matrix()
        P = T.copy()
        P[:3, 3] = g.position - self.pregrasp_distance * g.rotation[:, 2]
        doc.update({"hand": self.best_hand, "target_part": self.best_part, "pose": pose_json(T),
                    "pre_grasp": pose_json(P), "cost": g.cost, "overlap_rms_m": g.overlap_rms,
                    "score": next(s for h, p, c, s in self.candidates if c is g),
                    "poor_overlap": bool(g.overlap_rms > self.poor_overlap),
                    "active_constraints": g.active, "constraints": g.constraints,
                    "hand_size": list(g.hand.size), "optimiser": {"message": g.message, "iterations": g.iterations,
                                                                  "starts": g.starts}})
        return doc


def pose_json(T: np.ndarray) -> dict:
    """4x4 matrix, position and quaternion (x, y, z, w; scipy order) of a pose."""
    return {"matrix": T.tolist(), "position": T[:3, 3].tolist(),
            "quaternion_xyzw": Rotation.from_matrix(T[:3, :3]).as_quat().tolist()}


@dataclass
class GraspResult:
    objects: list[ObjectGrasp]
    plane: np.ndarray | None
    workspaces: dict[str, Workspace]
    options: GraspOptions
    warnings: list[str]
    source: str = ""
    timing: dict = field(default_factory=dict)
    skipped: dict[int, str] = field(default_factory=dict)  # segment id -> why it was not grasped

    def to_json(self) -> dict:
        o = self.options
        return {"source": self.source, "support_plane": None if self.plane is None else self.plane.tolist(),
                "hands": o.hands(), "workspaces": {h: w.to_json() for h, w in self.workspaces.items()},
                "hand_model": {"size": list(o.hand_model.size), "points": o.hand_model.n_points,
                               "palm_width": o.hand_model.palm_width, "thumb_length": o.hand_model.thumb_length,
                               "finger_length": o.hand_model.finger_length},
                "cones": [{"axis": c.axis, "direction": list(c.unit()), "aperture_deg": c.aperture_deg}
                          for c in o.cones],
                "lifting": o.lifting, "pregrasp_distance": o.pregrasp_distance,
                "reachability": "distance of the palm to the hand's workspace centre (a proxy: real inverse "
                                "kinematics is the robot's job)",
                "grasps": [g.to_json() for g in self.objects],
                "skipped_segments": [{"segment": sid, "reason": why} for sid, why in self.skipped.items()],
                "warnings": list(self.warnings),
                "timing_s": self.timing}


def superquadric_from_json(d: dict, where: str) -> Superquadric:
    """A Superquadric from a segments.json superquadric entry (its 11 'params')."""
    try:
        params = np.asarray(d["params"], dtype=np.float64)
        if params.shape != (11,) or not np.all(np.isfinite(params)):
            raise ValueError
    except (KeyError, TypeError, ValueError):
        raise GraspError(f"{where}: expected a superquadric with 11 finite 'params'") from None
    sq = Superquadric.from_params(params)
    if np.any(sq.size <= 0) or np.any(sq.exponents <= 0):
        raise GraspError(f"{where}: superquadric sizes and exponents must be > 0")
    # beyond these the solver's powers overflow (warnings, NaN poses): no segment of a scene is that large
    if np.any(sq.size > MAX_SQ_SIZE) or np.any(np.abs(sq.center) > MAX_SQ_CENTER) or np.any(sq.exponents < MIN_SQ_EXPONENT) \
            or np.any(sq.exponents > MAX_SQ_EXPONENT):
        raise GraspError(f"{where}: superquadric sizes {sq.size.tolist()} m, exponents {sq.exponents.tolist()}, centre "
                         f"{sq.center.tolist()} m out of range (expected sizes <= {MAX_SQ_SIZE:g} m, exponents "
                         f"{MIN_SQ_EXPONENT:g}..{MAX_SQ_EXPONENT:g}, centre within {MAX_SQ_CENTER:g} m)")
    return sq


def read_segments(path: str | os.PathLike) -> dict:
    """segments.json as a dict, or GraspError naming the file."""
    path = Path(path)
    if path.is_dir():
        path = path / "segments.json"
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise GraspError(f"{path}: no such file (expected a kinfu segment segments.json)") from None
    except (OSError, ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError, an integer of > 4300 digits
        raise GraspError(f"{path}: not a JSON file ({type(exc).__name__})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("segments"), list):
        raise GraspError(f"{path}: expected a kinfu segment segments.json with a 'segments' list")
    return doc


def _segment_id(s: dict, i: int, source: str) -> int:
    sid = s.get("id")
    if (isinstance(sid, bool) or not isinstance(sid, (int, float)) or not math.isfinite(sid)
            or int(sid) != sid):
        raise GraspError(f"{source}: segments[{i}].id is {sid!r}, expected an integer")
    return int(sid)


def _check_unique_ids(doc: dict, source: str) -> None:
    """Two segments with one id: which one a chosen segment id and a grasp's `segment` mean is a guess: refuse."""
    seen: dict[int, int] = {}
    for i, s in enumerate(doc["segments"]):
        if not isinstance(s, dict):
            raise GraspError(f"{source}: segments[{i}] is {type(s).__name__}, expected an object")
        if s.get("kind") != "object" and (isinstance(s.get("id"), bool) or not isinstance(s.get("id"), int)):
            continue  # only object segments need an integer id
        sid = _segment_id(s, i, source)
        if sid in seen:
            raise GraspError(f"{source}: segments[{i}].id {sid} repeats segments[{seen[sid]}].id: expected one "
                             f"segment per id")
        seen[sid] = i


def _box_problem(box, parts: list[Superquadric]) -> str | None:
    """Why the superquadric parts cannot be fits of the segment's points (its 'oriented_box'): a part whose centre
    lies outside the box grown on every side by the part's largest semi-axis, or a single superquadric whose
    largest side exceeds OVERSIZE_FACTOR x the box's (segment's 'oversized'); None when they fit or the segment
    has no (readable) box."""
    try:
        center = np.asarray(box["center"], dtype=np.float64)
        axes = np.asarray(box["axes"], dtype=np.float64)  # rows: the box's unit axes
        extents = np.asarray(box["extents"], dtype=np.float64)
        if center.shape != (3,) or axes.shape != (3, 3) or extents.shape != (3,) or not (
                np.all(np.isfinite(center)) and np.all(np.isfinite(axes)) and np.all(np.isfinite(extents))):
            return None
    except (KeyError, TypeError, ValueError):
        return None
    for k, q in enumerate(parts):
        local = np.abs(axes @ (q.center - center))
        reach = extents / 2 + float(np.max(q.size))
        if np.any(local > reach):
            outside = float(np.max(local - reach))
            name = "superquadric" if len(parts) == 1 else f"superquadric part {k}"
            return (f"its {name}'s centre {np.round(q.center, 3).tolist()} m lies {outside:.3g} m outside the box of "
                    f"its points (centre {np.round(center, 3).tolist()} m, sides {np.round(extents, 3).tolist()} m) "
                    f"grown by its size {float(np.max(q.size)):.3g} m: not a fit of its points")
    if len(parts) == 1 and (ratio := oversize(parts[0].size, extents)) > OVERSIZE_FACTOR:
        return (f"its superquadric's largest side {2 * float(np.max(parts[0].size)):.3g} m is {ratio:.1f}x the largest "
                f"side of the box of its points ({float(np.max(extents)):.3g} m; at most {OVERSIZE_FACTOR:g}x): "
                f"oversized, not a fit of its points")
    return None


def segment_parts(doc: dict, source: str) -> dict[int, list[Superquadric]]:
    """Object segment id -> its superquadric parts (the multi-superquadric parts when present)."""
    _check_unique_ids(doc, source)
    out = {}
    for i, s in enumerate(doc["segments"]):
        if s.get("kind") != "object":
            continue
        sid = _segment_id(s, i, source)
        multi = s.get("multi_superquadric") or {}
        if not isinstance(multi, dict) or not isinstance(multi.get("parts") or [], list):
            raise GraspError(f"{source}: segment {sid}: multi_superquadric is not an object with a 'parts' list")
        multi = multi.get("parts") or []
        if multi:
            out[sid] = [superquadric_from_json(p, f"{source}: segment {sid} part {i}") for i, p in enumerate(multi)]
        elif s.get("superquadric"):
            out[sid] = [superquadric_from_json(s["superquadric"], f"{source}: segment {sid}")]
    return out


def object_entries(doc: dict) -> dict[int, dict]:
    """segments.json's object segments by id, looked up once for everything asked about them (ids are unique:
    `_check_unique_ids`)."""
    return {s.get("id"): s for s in doc["segments"] if isinstance(s, dict) and s.get("kind") == "object"}


def doubtful_segments(entries: dict[int, dict], parts: dict[int, list[Superquadric]]) -> dict[int, str]:
    """Segment id -> why its superquadric(s) lie far from its points (`_box_problem`), for the segments of `parts`
    whose segments.json entry (`object_entries`) carries an oriented_box."""
    boxes = {sid: s.get("oriented_box") for sid, s in entries.items()}
    return {sid: why for sid, ps in parts.items()
            if isinstance(boxes.get(sid), dict) and (why := _box_problem(boxes[sid], ps))}


def nothing_to_grasp(doc: dict) -> str:
    """Why segments.json offers no superquadric: no object segment at all (a bare table: segment's warning says
    why), superquadrics turned off, or every fit failed (the first segment's reason)."""
    objects = [s for s in doc["segments"] if isinstance(s, dict) and s.get("kind") == "object"]
    if not objects:
        said = [w for w in doc.get("warnings") or [] if isinstance(w, str) and w.startswith("no objects")]
        return ("no object segment to grasp: kinfu segment found none"
                + (f" ({said[0].split('; ', 1)[-1]})" if said else ""))
    options = doc.get("options") if isinstance(doc.get("options"), dict) else {}
    failed = next(((s.get("id"), s["superquadric_error"]) for s in objects if s.get("superquadric_error")), None)
    if options.get("superquadrics") is False:
        why = "segmented without them: run kinfu segment with superquadrics"
    elif failed:
        why = f"segment {failed[0]}: {failed[1]}"
    else:
        why = "run kinfu segment with superquadrics"
    return f"no object segment has a superquadric to grasp (of {len(objects)}; {why})"


def fit_convergence(s: dict) -> tuple[bool | None, list[str]]:
    """Whether the fits a grasp of the segment (its segments.json entry `s`) rests on converged: its
    multi-superquadric's parts when it has them, else its superquadric (None when segments.json does not say), and
    the ones that did not, each named with its residual ('residual 19 mm', 'part 1, residual 3 mm')."""
    multi = s.get("multi_superquadric")
    parts = multi.get("parts") if isinstance(multi, dict) else None
    fits = list(enumerate(parts)) if isinstance(parts, list) and parts else [(None, s.get("superquadric"))]
    said = [(k, f) for k, f in fits if isinstance(f, dict) and isinstance(f.get("converged"), bool)]
    unfinished = []
    for k, f in said:
        if f["converged"]:
            continue
        residual = f.get("residual")
        try:
            mm = 1000 * float(residual) if isinstance(residual, (int, float)) and not isinstance(residual, bool) \
                else math.nan
        except OverflowError:  # an integer of hundreds of digits
            mm = math.nan
        unfinished.append(", ".join(([f"part {k}"] if k is not None else [])
                                    + ([f"residual {mm:.0f} mm"] if math.isfinite(mm) else [])))
    return (False if unfinished else True if said and len(said) == len(fits) else None), unfinished


def segment_flags(s: dict) -> dict:
    """The doubts a grasp of the segment (its segments.json entry `s`) inherits: 'touches_grid_faces' (the faces the
    grid cuts it at, [] when none) and 'fit_converged' (`fit_convergence`)."""
    faces = s.get("touches_grid_faces")
    return {"touches_grid_faces": list(faces) if isinstance(faces, list) else [],
            "fit_converged": fit_convergence(s)[0]}


def shape_doubts(entries: dict[int, dict], planned: list[int]) -> list[str]:
    """What segments.json (`object_entries`) doubts about the shapes of the segments grasped (`planned`): a
    superquadric fit that did not converge (its 'converged' false; for a multi-superquadric, its parts' fits), and
    segments the grid cuts off ('touches_grid_faces'): their grasps are planned all the same, and said."""
    unfinished, cut = [], []
    for sid in planned:
        s = entries.get(sid) or {}
        fits = fit_convergence(s)[1]
        if fits:
            unfinished.append(f"{sid}" + (f" ({'; '.join(fits)})" if any(fits) else ""))
        faces = s.get("touches_grid_faces")
        if isinstance(faces, list) and faces:
            cut.append(f"{sid} ({', '.join(str(f) for f in faces)})")
    out = []
    if unfinished:
        out.append(f"segment{'s' if len(unfinished) > 1 else ''} {', '.join(unfinished)}: the superquadric fit did "
                   f"not converge: {'their grasps rest' if len(unfinished) > 1 else 'its grasp rests'} on an "
                   f"unfinished shape")
    if cut:
        out.append(f"segment{'s' if len(cut) > 1 else ''} {', '.join(cut)} touch{'' if len(cut) > 1 else 'es'} the "
                   f"grid's faces: the grid cuts {'them' if len(cut) > 1 else 'it'} off, so "
                   f"{'their grasps are' if len(cut) > 1 else 'its grasp is'} planned on the part inside the grid only")
    return out


def support_plane(doc: dict, source: str) -> np.ndarray | None:
    """segments.json's support plane (a, b, c, d) with a unit normal, None when absent; GraspError naming
    `source` when it is not four finite numbers."""
    p = doc.get("support_plane")
    if p is None:
        return None
    try:
        p = np.asarray(p, dtype=np.float64)
    except (TypeError, ValueError):
        p = np.zeros(0)
    if p.shape != (4,) or not np.all(np.isfinite(p)) or np.linalg.norm(p[:3]) < 1e-9:
        raise GraspError(f"{source}: support_plane must be four finite numbers a, b, c, d")
    return p / np.linalg.norm(p[:3])


def grasp_object(sid: int, parts: list[Superquadric], plane: np.ndarray | None, workspaces: dict[str, Workspace],
                 options: GraspOptions) -> ObjectGrasp:
    """Every (hand, target part) candidate of one object and the best by score (module docstring)."""
    t0, c0 = time.perf_counter(), time.process_time()
    cands = []
    S = len(parts)
    for hand in options.hands():
        ws = workspaces[hand]
        cons = GraspConstraints(plane, ws, list(options.cones))
        for p, target in enumerate(parts):
            obstacles = [q for k, q in enumerate(parts) if k != p]
            g = grasp_part(target, options.hand_model, cons, obstacles, lifting=options.lifting,
                           n_starts=options.n_starts, max_iter=options.max_iter)
            reach = float(np.linalg.norm(g.position - ws.center()))
            score = g.overlap_rms + options.reach_weight * reach
            if S > 1:
                score += options.obstacle_weight * (S - 1) / max(g.obstacle_distance, 1e-9)
            cands.append((hand, p, g, float(score)))
    ok = [c for c in cands if c[2].converged]
    best = min(ok, key=lambda c: c[3]) if ok else None
    return ObjectGrasp(sid, parts, best[2] if best else None, best[0] if best else None, best[1] if best else None,
                       cands, options.pregrasp_distance, options.poor_overlap, time.perf_counter() - t0, time.process_time() - c0)


def plan_grasps(segments: str | os.PathLike | dict, options: GraspOptions | None = None, progress=None,
                source: str | None = None) -> GraspResult:
    """The `kinfu grasp` driver: read segments.json (a path or its parsed dict), check the options and the
    workspaces against the support plane, then grasp every object segment. `progress` wraps the segment
    list (a tqdm-like callable) when given."""
    t0 = time.perf_counter()
    options = options or GraspOptions()
    options.validate()
    source = source or (str(segments) if not isinstance(segments, dict) else "segments")
    doc = read_segments(segments) if not isinstance(segments, dict) else segments
    plane = support_plane(doc, source)
    parts = segment_parts(doc, source)
    if options.segment_ids is not None:
        missing = [s for s in options.segment_ids if s not in parts]
        if missing:
            raise ConfigError(f"{source}: no object segment with a superquadric has id {missing[0]} (ids with one: "
                              f"{sorted(parts)})", parameter="segment_ids")
        parts = {s: parts[s] for s in options.segment_ids}
    if not parts:
        raise GraspError(f"{source}: {nothing_to_grasp(doc)}")
    # a grasp of a superquadric away from its object looks right and grasps air; it would also move the workspaces
    entries = object_entries(doc)
    skipped = doubtful_segments(entries, parts)
    if skipped and len(skipped) == len(parts):
        sid, why = next(iter(skipped.items()))
        raise GraspError(f"{source}: no object segment has a superquadric that fits its points (segment {sid}: "
                         f"{why}); run kinfu segment again")
    warnings = [f"segment {sid}: {why}: skipped (listed in skipped_segments)" for sid, why in skipped.items()]
    parts = {sid: ps for sid, ps in parts.items() if sid not in skipped}
    warnings += shape_doubts(entries, list(parts))
    if plane is None:
        warnings.append("segments.json has no support plane: grasps are not kept above any table")
    up = plane[:3] if plane is not None else np.array([0.0, 0.0, 1.0])
    centres = np.array([q.center for ps in parts.values() for q in ps])
    workspaces = dict(options.workspaces or {})
    auto = default_workspaces(centres, up)
    for h in options.hands():
        workspaces.setdefault(h, auto[h])
        check_workspace(workspaces[h], plane, f"workspace_{h}")
    ids = list(parts)
    # extreme (valid) superquadrics overflow the inside-outside powers to inf: that candidate then fails its
    # constraints and the object is reported without a grasp, so numpy's overflow warnings are only noise
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        objs = [grasp_object(sid, parts[sid], plane, workspaces, options)
                for sid in (progress(ids) if progress is not None else ids)]
    for o in objs:  # what segments.json doubts about each shape, on the grasp itself (shape_doubts says it too)
        o.shape_flags = segment_flags(entries.get(o.segment) or {})
    for o in objs:
        if plane is not None and any(q.center @ plane[:3] + plane[3] < 0 for q in o.parts):
            warnings.append(f"segment {o.segment}: its superquadric's centre is below the support plane (a poor "
                            f"fit): its grasp is unreliable")
        if o.best is not None and o.best.overlap_rms > options.poor_overlap:
            warnings.append(f"segment {o.segment}: the hand ellipsoid stays {o.best.overlap_rms * 1000:.0f} mm (RMS) "
                            f"from the object's superquadric (> poor_overlap {options.poor_overlap * 1000:.0f} mm): "
                            f"a poor grasp, flagged poor_overlap")
        if o.best is None:
            warnings.append(f"segment {o.segment}: no grasp satisfies every constraint (reported with converged "
                            f"false, no pose)")
    return GraspResult(objs, plane, {h: workspaces[h] for h in options.hands()}, options, warnings, source,
                       {"total": time.perf_counter() - t0}, skipped)
