"""`kinfu nbv` as two library calls, one per planner; each returns a result whose `to_json()` is views.json.

- `rank_poi_views(volume_path, pois_path, camera, options)`: the paper's planner (RAS 2016): optionally
  ForgetAround every POI, then rank the viewing sphere (or given candidates) around each POI -> `PoiViews`.
- `rank_object_views(volume_path, camera, ...)`: the object-driven planner (thesis Alg. 4): views at the
  contours of the most salient segment -> `ObjectViews`.

Both work along the volume's up direction (stored by fusion; `resolve_up`): the viewing sphere, the table
height and the below-table rejection follow it. A result that is empty for a structural reason (every
candidate rejected, no candidate at all) says so in its `warnings`, with the counts per reason.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.grid import OCCUPIED, TernaryGrid, check_up
from kinfu_cli.core.poses import matrix_to_quaternion
from kinfu_cli.core.progress import progress_bar
from kinfu_cli.fusion.volume import load_grid
from kinfu_cli.nbv.gains import get_gain
from kinfu_cli.nbv.objects import W_TH, ObjectPlan, known_grid, nbv_scorer, plan_object_views_for_volume
from kinfu_cli.nbv.ranking import (PoiRanking, check_region_inside, estimate_table_z, forget_around,
                                   least_blocked_share, load_pois, rank_poi, sphere_counts, sphere_outside_share)
from kinfu_cli.nbv.raycast import RayVolume
from kinfu_cli.nbv.viewpoints import MAX_RUN_VIEWS, PAPER_SPHERE, SphereSpec, read_candidates
from kinfu_cli.segmentation.pipeline import load_segment_input

# a POI is unreachable when at least this share of every valid view's rays stops on unknown space outside S(POI)
UNREACHABLE_SHARE = 0.5
# ... and S(POI) still holds this share of unknown voxels (a region known all but a few voxels is reconstructed)
UNREACHABLE_UNKNOWN = 0.01
# a POI called reconstructed while this share of its candidates were rejected inside unobserved space (and
# UNREACHABLE_UNKNOWN of S(POI) unknown) is a warning: the fuzzed tabletop's 952 of 960; the synthetic objects
# scene's 648 of 960 (68 %, its unknown voxels a table's interior) and a y-down room's 52 of 96 are not
FEW_VALID_REJECTED = 0.8
# warn when at least this share of S(POI) lies outside the grid: its gains and the IncTh verdict only see the rest
OUTSIDE_WARN_SHARE = 0.2
TableZ = str | float | None  # "auto" (found in the volume), "none" / None (no table), or a height in metres


@dataclass(frozen=True)
class NbvOptions:
    """Options of `rank_poi_views`.

    gain: a name of `gains.GAINS`; clear: ForgetAround every POI first; top: views listed per POI
    (0 = all); candidates: a pose file scored instead of the viewing `sphere`; poi_radius: replaces each
    POI's radius (m); inc_th: IncTh (None: 1 % of the pixels that see S(POI)); table_z: see `TableZ`;
    clearance: reject sensor positions this close (m) to occupied/unknown voxels (outside the grid counts as unknown); share_rolls: rolls
    of one position share their rays; optimistic: unknown voxels outside S(POI) do not stop rays; up:
    the world's up direction instead of the volume's.
    """

    gain: str = "unknown"
    clear: bool = False
    top: int = 10
    candidates: str | os.PathLike | None = None
    sphere: SphereSpec = PAPER_SPHERE
    poi_radius: float | None = None
    inc_th: float | None = None
    table_z: TableZ = "auto"
    clearance: float = 0.0
    share_rolls: bool = True
    optimistic: bool = False
    up: tuple[float, float, float] | None = None  # the world's up; None: the volume's (z when it has none)

    def validate(self) -> None:
        """ConfigError naming the first option out of its range."""
        get_gain(self.gain)
        if self.poi_radius is not None:
            check_number(self.poi_radius, "poi_radius", 0, 100, low_open=True, unit="m")
        if self.inc_th is not None:
            check_number(self.inc_th, "inc_th", 0)
        check_number(self.clearance, "clearance", 0, 100, unit="m")
        if self.up is not None:
            check_up(self.up, "up")


def resolve_up(grid: TernaryGrid, up=None) -> tuple[np.ndarray, str]:
    """The up direction to plan with and where it came from: "option" (`up` given), "volume" (the grid's,
    stored by fusion), or "assumed-z" (a volume that does not know its up)."""
    if up is not None:
        return check_up(up, "up"), "option"
    if grid.up is not None:
        return grid.up, "volume"
    return np.array([0.0, 0.0, 1.0]), "assumed-z"


def _up_words(up: np.ndarray, source: str) -> str:
    why = {"volume": "the volume's", "option": "given", "assumed-z": "assumed: the volume has none"}.get(source, source)
    return f"up {[round(float(v), 3) for v in up]} ({why})"


def rejection_warning(what: str, rejected: dict[str, int], total: int, table_z: float | None, up: np.ndarray,
                      up_source: str) -> str:
    """The warning of a planner whose every candidate view was rejected: counts per reason, and the table
    height and up direction when the table rejected some."""
    counts = ", ".join(f"{k} {v}" for k, v in rejected.items() if v)
    msg = f"{what}: all {total} candidate views rejected ({counts}): no view to rank"
    if rejected.get("below_table") and table_z is not None:
        msg += f"; the table is at height {table_z:.3f} m along {_up_words(up, up_source)}"
    return msg


def resolve_table_z(grid: TernaryGrid, table_z: TableZ, up=None) -> float | None:
    """The table height in metres along `up` (default z) that `table_z` asks for, or None for no table."""
    if table_z is None or table_z == "none":
        return None
    if table_z == "auto":
        return estimate_table_z(grid, up=up)
    return float(table_z)


@dataclass
class PoiViews:
    """Result of `rank_poi_views`: the ranked views of every POI.

    grid is the volume as ranked (after ForgetAround with options.clear); table_z the height used (along up).
    """

    volume_path: str
    pois_path: str
    options: NbvOptions
    camera: CameraModel
    grid: TernaryGrid
    table_z: float | None
    rankings: list[PoiRanking]
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    up_source: str = "assumed-z"
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        """The views.json document."""
        opts = self.options
        return {
            "volume": self.volume_path, "pois_file": self.pois_path, "gain": opts.gain,
            "gain_unit": get_gain(opts.gain).unit, "cleared": bool(opts.clear),
            "candidates": str(opts.candidates) if opts.candidates is not None else {"sphere": opts.sphere.to_json()},
            "camera": self.camera.to_dict(), "table_z": self.table_z, "up": self.up.tolist(),
            "up_source": self.up_source, "clearance": opts.clearance,
            "share_rolls": opts.share_rolls, "optimistic": opts.optimistic,
            "voxel_size": self.grid.voxel_size, "shape": list(self.grid.shape),
            "pois": [r.to_dict(top=opts.top) for r in self.rankings], "warnings": list(self.warnings),
        }


def _view_bar(total: int, quiet: bool):
    """A progress bar over the candidate views on stderr, or None when progress is off."""
    return progress_bar(total, desc="nbv candidates", unit="view", quiet=quiet)


# most rays one run may cast (candidate views x sensor pixels): what MAX_RUN_VIEWS costs at the Kinect's 640 x 480
# (2-7 min at 0.1-0.4 ms a view). A view's cost grows with the pixels, and faster than them (16000 x 1000 px: 145 s
# for 2 POIs, ~75 ms a view, measured by the fuzzing session), so at the largest sensor the bound is ~25 min; the
# view bound alone let a 4096 x 4096 sensor run for days.
MAX_RUN_RAYS = MAX_RUN_VIEWS * 640 * 480


def check_run_size(pois_path, n_pois: int, opts: NbvOptions, n_candidates: int | None = None,
                   pixels: int | None = None) -> int:
    """The number of candidate views the run ranks (every POI's sphere, or the candidate file once per POI);
    ConfigError naming the POI file and the sphere options (or the candidate file) when it exceeds
    MAX_RUN_VIEWS, or, with the sensor's `pixels`, when views x pixels exceed MAX_RUN_RAYS, before any pose is
    made."""
    per_poi = opts.sphere.view_count() if n_candidates is None else n_candidates
    total = n_pois * per_poi
    if pixels is not None and total <= MAX_RUN_VIEWS and total * pixels > MAX_RUN_RAYS:
        raise ConfigError(f"{pois_path}: {total:,} candidate views x {pixels:,} sensor pixels = {total * pixels:.3g} "
                          f"rays, more than the {MAX_RUN_RAYS:.3g} one run casts (hours of ray casting); use a "
                          f"smaller sensor image, fewer views (larger sphere steps) or fewer POIs a run")
    if total > MAX_RUN_VIEWS:
        what = "views on each viewing sphere" if n_candidates is None else f"candidates in {opts.candidates}"
        fix = ("use larger sphere steps or a narrower latitude range" if n_candidates is None
               else "give fewer candidates")
        raise ConfigError(f"{pois_path}: {n_pois:,} POIs x {per_poi:,} {what} = {total:,} candidate views, more "
                          f"than the {MAX_RUN_VIEWS:,} one run ranks (~1.2 kB of memory each); rank the POIs in "
                          f"several runs (split the file) or {fix}",
                          parameter="lon_step/lat_step/roll_step" if n_candidates is None else "candidates")
    return total


def rank_poi_views(volume_path: str | os.PathLike, pois_path: str | os.PathLike, camera: CameraModel,
                   options: NbvOptions | None = None, *, quiet: bool = True) -> PoiViews:
    """Rank the views of every POI of `pois_path` in the volume (a ternary.npz or a volume.npz)."""
    opts = options or NbvOptions()
    opts.validate()
    pois = load_pois(pois_path, opts.poi_radius)
    candidates = read_candidates(opts.candidates) if opts.candidates is not None else None
    check_run_size(pois_path, len(pois), opts, None if candidates is None else len(candidates),
                   camera.width * camera.height)
    grid = load_grid(volume_path)
    s_voxels, s_unknown = [], []
    for p in pois:
        check_region_inside(grid, p.position, f"{pois_path}: POI {p.id}")
        unknown, total = sphere_counts(grid, p.position, p.radius)
        s_voxels.append(total)
        s_unknown.append(unknown)
        _check_region_voxels(grid, p, total, pois_path, opts.poi_radius is not None)
    outside = [sphere_outside_share(grid, p.position, p.radius) for p in pois]
    cleared = {p.id: forget_around(grid, p.position, p.radius) for p in pois} if opts.clear else {}
    if opts.clear:  # ForgetAround left every voxel of every S(POI) unknown
        s_unknown = list(s_voxels)
    up, up_source = resolve_up(grid, opts.up)
    table_z = resolve_table_z(grid, opts.table_z, up)
    vol = RayVolume.from_grid(grid)
    per_poi = [candidates if candidates is not None else opts.sphere.viewpoints(p.position, up=up) for p in pois]
    bar = _view_bar(sum(len(c) for c in per_poi), quiet)
    rankings = []
    try:
        for p, poses, out_share, n_voxels in zip(pois, per_poi, outside, s_voxels):
            r = rank_poi(vol, p.position, camera, poi_id=p.id, radius=p.radius, gain=opts.gain, candidates=poses,
                         inc_th=opts.inc_th, table_z=table_z, clearance=opts.clearance,
                         share_rolls=opts.share_rolls, optimistic=opts.optimistic,
                         progress_cb=bar.update if bar is not None else None, up=up)
            r.extra.update(sphere_voxels=n_voxels, outside_share=round(out_share, 3))
            if opts.clear:
                r.extra["cleared_voxels"] = cleared[p.id]
            rankings.append(r)
    finally:
        if bar is not None:
            bar.close()
    warnings = [_outside_warning(r, grid) for r in rankings if r.extra["outside_share"] >= OUTSIDE_WARN_SHARE]
    warnings += [rejection_warning(f"POI {r.poi_id}", r.scores.rejected(), len(r.scores.reasons), table_z, up,
                                  up_source) for r in rankings if len(r.scores.reasons) and not r.scores.valid.any()]
    warnings += [w for r, unknown in zip(rankings, s_unknown)
                 if (w := _unreachable(r, opts.optimistic, unknown) or _few_valid_views(r, unknown))]
    warnings += [f"POI {r.poi_id}: every valid view scores 0 on the {opts.gain} gain though S(POI) is not "
                 f"reconstructed (best unknown gain {r.scores.gains['unknown'][r.scores.valid].max():.0f} rays): the "
                 f"order of its views says nothing; rank with the unknown gain"
                 for r in rankings if not r.reconstructed and not r.extra.get("unreachable")
                 and r.scores.valid.any() and r.best_gain <= 0]
    return PoiViews(str(volume_path), str(pois_path), opts, camera, grid, table_z, rankings, up, up_source, warnings)


def _check_region_voxels(grid: TernaryGrid, poi, voxels: int, pois_path, radius_given: bool) -> None:
    """Refuse a POI whose S(POI) holds no voxel centre: nothing in it can be seen, so its IncTh verdict would
    read "reconstructed" on no evidence. A radius of half a voxel's diagonal always holds one."""
    if voxels:  # voxel centres in S(POI)
        return
    need = grid.voxel_size * np.sqrt(3) / 2
    msg = (f"S(POI) of radius {poi.radius:g} m around POI {poi.id} holds no voxel centre of the volume (voxel size "
           f"{grid.voxel_size:g} m): nothing in it to rank views for or to call reconstructed; expected a radius of "
           f"at least {need:.3f} m")
    if radius_given:
        raise ConfigError(msg, parameter="poi_radius")
    raise VolumeError(f"{pois_path}: {msg} (or replace the file's radii with poi_radius)")


def _outside_warning(r: PoiRanking, grid: TernaryGrid) -> str:
    """The warning of a POI whose S(POI) lies partly outside the grid (share in r.extra["outside_share"])."""
    lo = grid.origin
    hi = grid.origin + np.array(grid.shape) * grid.voxel_size
    box = " x ".join(f"[{a:.3f}..{b:.3f}]" for a, b in zip(lo, hi))
    return (f"POI {r.poi_id}: {100 * r.extra['outside_share']:.0f} % of S(POI) (radius {r.radius:g} m) lies outside "
            f"the volume {box} m: that part was never mapped, so the gains and the IncTh verdict only cover the "
            f"{r.extra['sphere_voxels']} voxels inside (a smaller radius, or a volume fused with a larger grid)")


def _few_valid_views(r: PoiRanking, unknown: int) -> str:
    """A warning when a POI is called reconstructed (no valid view's gain reaches IncTh) while S(POI) still holds
    UNREACHABLE_UNKNOWN of unknown voxels and most candidates (FEW_VALID_REJECTED) were rejected for standing in
    unobserved space: the paper's verdict covers only what the few valid views see. Not turned into "unreachable":
    the unknown voxels may lie inside solid objects (a table's interior), which no view sees, and the rejected
    views, cast as if their space were free, would see through unobserved faces into them (a false alarm on the
    synthetic objects scene); "" otherwise. unknown: the unknown voxels of S(POI) (of r.extra["sphere_voxels"])."""
    if not r.reconstructed or not len(r.scores.reasons):
        return ""
    inside = sum(why == "inside_unknown" for why in r.scores.reasons)
    if inside < FEW_VALID_REJECTED * len(r.scores.reasons):
        return ""
    total = r.extra["sphere_voxels"]
    if unknown < UNREACHABLE_UNKNOWN * total:
        return ""
    n_valid = int(r.scores.valid.sum())
    return (f"POI {r.poi_id}: reconstructed by the IncTh rule from only {n_valid} of {len(r.scores.reasons)} "
            f"candidate views ({inside} were rejected standing in unobserved space), while S(POI) still holds "
            f"{unknown} unknown of {total} voxels ({100 * unknown / total:.0f} %; some may lie inside solid objects): "
            f"the verdict covers only what those views see")


def _unreachable(r: PoiRanking, optimistic: bool, unknown: int) -> str:
    """Mark a POI whose region no valid view can see (every view's rays mostly stop on unobserved space before
    S(POI)) while S(POI) still holds unknown voxels (UNREACHABLE_UNKNOWN of it): the paper's IncTh test would
    call it reconstructed, but its small gain only says the way there was never observed. Such a POI is
    `unreachable` and not reconstructed; returns its warning ("" otherwise). unknown: the unknown voxels of S(POI)."""
    share = None if optimistic else least_blocked_share(r.scores)
    s_voxels = r.extra["sphere_voxels"]
    r.extra["unreachable"] = bool(share is not None and share >= UNREACHABLE_SHARE
                                  and unknown >= UNREACHABLE_UNKNOWN * s_voxels and r.reconstructed)
    if not r.extra["unreachable"]:
        return ""
    r.reconstructed = False
    return (f"POI {r.poi_id}: no candidate view sees S(POI): at least {100 * share:.0f} % of every valid view's rays "
            f"stop on unobserved space before it, and it holds {unknown} unknown voxels; not reconstructed but "
            f"unreachable with this volume (too few frames, or the scan never looked there; the optimistic "
            f"planner lets rays pass unknown space)")


@dataclass
class ObjectViews:
    """Result of `rank_object_views`: the object-driven plan and what it was computed with."""

    volume_path: str
    gain: str
    camera: CameraModel
    grid: TernaryGrid
    table_z: float | None
    score_threshold: float
    plan: ObjectPlan
    top: int = 10  # views listed (0 = all)
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    up_source: str = "assumed-z"
    warnings: list[str] = field(default_factory=list)
    empty_reason: str | None = None  # why there is no view when that is structural (not "all reconstructed")
    rejected: dict[str, int] = field(default_factory=dict)  # candidate views rejected, per reason
    w_th: float | None = W_TH  # observations for a voxel to count as known at the contours (None: no weights)

    def to_json(self) -> dict:
        """The views.json document of the objects mode: the plan plus each view's position and quaternion."""
        doc = self.plan.to_json(top=self.top or 10**9)
        for v in doc["views"]:
            T = np.asarray(v["pose"])
            v.update(position=T[:3, 3].tolist(), quaternion=matrix_to_quaternion(T[:3, :3]).tolist(), gain=v["score"])
        return {"mode": "objects", "volume": self.volume_path, "gain": self.gain,
                "gain_unit": get_gain(self.gain).unit, "camera": self.camera.to_dict(), "table_z": self.table_z,
                "up": self.up.tolist(), "up_source": self.up_source, "candidates_rejected": dict(self.rejected),
                "empty_reason": self.empty_reason,
                "voxel_size": self.grid.voxel_size, "shape": list(self.grid.shape),
                "score_threshold": self.score_threshold, "w_th": self.w_th, **doc, "warnings": list(self.warnings)}


def rank_object_views(volume_path: str | os.PathLike, camera: CameraModel, *, gain: str = "unknown",
                      table_z: TableZ = "auto", score_threshold: float = 0.0, top: int = 10,
                      up=None) -> ObjectViews:
    """The object-driven planner (thesis Alg. 4, `nbv.objects`) on a volume, scored with this package's
    ray caster: the best views of the most salient segment whose best score exceeds `score_threshold`.
    up: the world's up instead of the volume's."""
    get_gain(gain)
    volume = load_segment_input(volume_path)
    grid = volume.ternary_grid() if hasattr(volume, "ternary_grid") else volume
    up, up_source = resolve_up(grid, up)
    tz = resolve_table_z(grid, table_z, up)
    tally: dict[str, int] = {}
    weights = volume.weights() if hasattr(volume, "weights") else None  # one extraction for score and contours
    known, _ = known_grid(volume, weights=weights)
    plan = plan_object_views_for_volume(
        volume, camera, scorer=nbv_scorer(known, camera, gain=gain, table_z=tz, up=up, tally=tally), weights=weights,
        score_threshold=score_threshold, table_z=tz, up=up)
    rejected = {k: v for k, v in tally.items() if k not in ("views", "valid")}
    empty = None
    if plan.pose is None:
        if plan.candidates_total == 0 and weights is not None and not np.any(known.labels == OCCUPIED):
            empty = (f"no candidate views: the volume has no contour point, as no occupied voxel was observed the "
                     f"W_th = {W_TH:g} times the planner needs to count it as known (a volume fused from fewer "
                     f"frames?)")
        elif plan.candidates_total == 0:
            empty = "no candidate views: the volume has no contour point (observed surface next to unknown space)"
        elif plan.candidates_evaluated == 0:
            empty = (f"no candidate views near a segment: {plan.candidates_total} candidates at the contours, "
                     f"{len(plan.attempts)} segments tried, none with a contour point")
        elif tally.get("views", 0) and not tally.get("valid", 0):
            empty = rejection_warning("objects", rejected, tally["views"], tz, up, up_source)
    warnings = ([empty] if empty else []) + object_plan_doubts(plan, grid, score_threshold, empty is not None)
    weighted = hasattr(volume, "weights")
    if not weighted:
        warnings.append(f"{volume_path} has no fusion weights (a ternary grid): W_th = {W_TH:g} is not applied, "
                        "every observed voxel counts as known; give the fused volume.npz to apply it")
    return ObjectViews(str(volume_path), gain, camera, grid, tz, score_threshold, plan, top, up, up_source,
                       warnings, empty, rejected, W_TH if weighted else None)


def object_plan_doubts(plan: ObjectPlan, grid: TernaryGrid, score_threshold: float, empty: bool) -> list[str]:
    """The object-driven plan's results that look right but rest on part of the evidence (the POI mode's
    OUTSIDE_WARN_SHARE and FEW_VALID_REJECTED checks, per segment): the segment planned for cut by a grid face,
    or its scored region mostly outside the grid; segments passed over as reconstructed that the grid cuts (beyond
    the face there is no voxel, so no contour point and no score says that side is unseen; contours take the
    outside as no evidence); segments passed over because every candidate of theirs was rejected; a
    "reconstructed" verdict from few valid views. `empty`: the plan is empty for a structural reason already said
    (every candidate rejected, no contour point)."""
    out = []
    chosen = plan.attempts[-1] if plan.pose is not None and plan.attempts else None
    passed = plan.attempts[:-1] if chosen is not None else plan.attempts
    if chosen is not None:
        share = sphere_outside_share(grid, plan.region_center, plan.region_radius)
        why = []
        if chosen.touches_grid_faces:
            why.append(f"the grid cuts it at its {_faces(chosen.touches_grid_faces)}, so its side beyond was never "
                       f"mapped and no contour point or score stands for it")
        if share >= OUTSIDE_WARN_SHARE:
            why.append(f"{100 * share:.0f} % of the region its views are scored on (radius {plan.region_radius:.2f} m) "
                       f"lies outside the volume, where no unknown voxel is counted")
        if why:
            out.append(f"segment {chosen.segment_id}, the one planned for: {'; '.join(why)}: its views cover only the "
                       f"part inside the grid (fuse again with a grid holding the whole object)")
    scored = [a for a in passed if a.candidates and a.rejected is not None]
    blind = [a for a in scored if a.valid == 0]
    cut = [a for a in passed if a.touches_grid_faces and a.valid != 0]
    if cut:
        them = "them" if len(cut) > 1 else "it"
        out.append(f"segment{_s(cut)} {', '.join(f'{a.segment_id} ({_faces(a.touches_grid_faces)})' for a in cut)} "
                   f"passed over as reconstructed though the grid cuts {them} there: beyond a face there is no voxel, "
                   f"so no contour point or score says that side is unseen (fuse again with a grid holding the whole "
                   f"object)")
    if empty:  # every candidate rejected, or none at all: said by the empty reason
        return out
    if blind and chosen is not None:
        out.append(f"segment{_s(blind)} {', '.join(f'{a.segment_id} ({a.candidates} candidates)' for a in blind)} "
                   f"passed over with every candidate view rejected ({_reasons(blind)}): no view of "
                   f"{'them' if len(blind) > 1 else 'it'} was scored, and the plan is for the less salient segment "
                   f"{chosen.segment_id}")
    if chosen is None and scored:
        total = sum(a.candidates for a in scored)
        valid = sum(a.valid for a in scored)
        unobserved = sum(a.rejected.get("inside_unknown", 0) for a in scored)
        if unobserved >= FEW_VALID_REJECTED * total or blind:
            none = f"; segment{_s(blind)} {', '.join(str(a.segment_id) for a in blind)} had none" if blind else ""
            out.append(f"no view scores above {score_threshold:g}, judged from only {valid} valid of {total} "
                       f"candidate views of the segments tried (rejected: {_reasons(scored)}{none}): the verdict that "
                       f"the objects are reconstructed covers only what those views see")
    return out


def _s(items) -> str:
    return "s" if len(items) > 1 else ""


def _faces(faces: list[str]) -> str:
    return f"{', '.join(faces)} face{_s(faces)}"


def _reasons(attempts: list) -> str:
    """The attempts' rejected candidates summed per reason: "inside_unknown 40, below_table 3"."""
    sums: dict[str, int] = {}
    for a in attempts:
        for k, v in a.rejected.items():
            sums[k] = sums.get(k, 0) + v
    return ", ".join(f"{k} {v}" for k, v in sums.items() if v) or "none"
