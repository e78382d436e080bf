"""Fuse a recording into a TernaryVolume: the driver of `kinfu fuse`.

`fuse_recording(path, ...)` reads the selected depth frames, filters them, places the grid, tracks the camera
where asked and integrates every frame, then reads out the ternary grid, mesh and cloud: a FusionResult.
It writes nothing; fusion.outputs writes the files and the report. Steps, in order:
1. check the arguments and the clear spheres, load the initial volume (or check the grid settings);
2. open the recording, detect roles, choose where the camera poses come from (`_pose_plan`); with size
   'auto', size the grid from a first pass over the frames (`_auto_grid`, fusion.extent);
3. stream frames through the depth filters (`DepthFilter`) into the integrator (`_Integrator`), which
   places the grid on the first frames and tracks with ICP in the icp and hint modes; frames whose tracking
   is lost are not fused, and more of them than max_lost (a share of the tracked frames) fail the run;
4. clear spheres (after fusing unless continuing a volume) and read out labels, mesh and cloud; warn when
   occupied voxels touch a face of the grid (the scene goes on beyond it).
`track_frames(volume, frames)` runs step 3's tracking integrator on frames held in memory (benchmarks, tests).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, RecordingError, VolumeError
from kinfu_cli.core.grid import TernaryGrid, check_up
from kinfu_cli.core.pois import poi_frame_warnings, read_pois
from kinfu_cli.core.progress import progress
from kinfu_cli.core.volume_file import MAX_COORDINATE_M
from kinfu_cli.fusion import filters
from kinfu_cli.fusion.color_mode import check_color_mode
from kinfu_cli.fusion.extent import (SURVEY_FRAMES, AutoGrid, auto_grid, budget_bytes, cut_faces, face_contacts,
                                    survey)
from kinfu_cli.fusion.mesh import mesh_cloud
from kinfu_cli.fusion.placement import default_origin
from kinfu_cli.fusion.tracking import (LOSS_CHECKS, MAX_PHOTO_WEIGHT, MAX_SPEED_M_S, MIN_TRACKING_WIDTH,
                                       PHOTO_WEIGHT, POSE_MODES, FrameToModelTracker, TrackResult, predict_pose)
from kinfu_cli.fusion.up import choose_up
from kinfu_cli.fusion.volume import DEFAULT_TRUNCATION_M, MIN_TRUNCATION_VOXELS, TernaryVolume, load_volume
from kinfu_cli.io.frames import check_window, iter_frames, window_depth_count
from kinfu_cli.io.messages import header_frame
from kinfu_cli.io.recording import Recording, open_recording
from kinfu_cli.io.rgbd_frame import (DROP_CHAIN_BROKEN, DROP_EMPTY, DROP_NO_POSE, DROP_NO_POSE_TOPIC, MAX_16BIT_MM,
                                     FrameStats, RGBDFrame)
from kinfu_cli.io.roles import Roles, detect_roles
from kinfu_cli.io.tf_buffer import TfBuffer
from kinfu_cli.io.world_up import read_world_up

if TYPE_CHECKING:  # open3d only for the annotations
    import open3d as o3d

# frames whose observed points centre the grid; with icp the first only (the others have no pose until tracked)
PLACEMENT_FRAMES = 5
# how the report counts frames not fused because tracking lost them
DROP_LOST = "tracking lost (not fused)"
# size 'auto' without camera poses (icp from the first frame): the first frame's box, grown by this share of its
# extent on each side, for what the camera turns to later (the face-contact warning says when it was not enough)
ICP_GROW = 0.5
# tracked poses farther than this (RMS over the frames) from the recording's own camera poses are reported: KinFu's
# tracking is good to about 1 cm (7-Scenes frames 0-59: 0.67 cm), and 2 cm already blurs a 6 mm grid by 3 voxels
DRIFT_WARN_M = 0.02
# more than this share of tracked frames found only by the wider re-localisation search is reported (7-Scenes: 0)
RELOCALISED_WARN = 0.2
# a frame fused with fewer of its valid readings than this share inside the grid added (next to) no surface to it:
# its pose is wrong (a TF that jumps) or the grid leaves out what it saw; it is reported (frames.outside_grid). Good
# poses keep far more: a 0.5 m grid on the tabletop sample 26 % of every frame, a 0.5 m corner of a synth scene
# 12 %; frames a TF moved 5 m away 0 % (stray readings would pass a test of none at all)
IN_GRID_MIN_SHARE = 0.01


@dataclass
class FusionResult:
    """What fusing a recording gave: the volume and its read-out, and how it was made (for the report)."""

    recording: str
    roles: Roles
    pose_mode: str  # forced, icp, hint or topic
    pose_source: str  # where the poses came from, in words
    volume: TernaryVolume
    placement: str  # how the grid was placed
    frame_stats: FrameStats  # frames read, skipped and dropped while assembling
    frames_used: int
    dropped: dict[str, int]  # reason -> frames, assembling and filtering
    tracking: list[dict] | None  # one entry per tracked frame; None without tracking
    depth_filter: DepthFilter
    every: int
    start_s: float | None
    end_s: float | None
    cleared_spheres: list[dict]
    warnings: list[str]
    grid: TernaryGrid
    counts: dict[str, int]
    bounding_box: dict[str, dict | None]  # occupied and observed voxels
    mesh: o3d.geometry.TriangleMesh
    cloud: o3d.geometry.PointCloud
    timing: dict[str, float] = field(default_factory=dict)  # seconds per step
    started: float = 0.0  # time.perf_counter() when fusing began
    up: dict = field(default_factory=dict)  # fusion.up.UpChoice.to_json(): up, source and the evidence
    grid_sizing: dict = field(default_factory=dict)  # mode given, init or auto (the observed box, budget, cap)
    face_contacts: dict[str, int] = field(default_factory=dict)  # occupied voxels on each face of the grid
    notes: list[str] = field(default_factory=list)  # what the run chose by itself (a command may print them)
    camera_stamps_ns: list[int] = field(default_factory=list)  # stamp of each frame fused, with ...
    camera_poses: list[np.ndarray] = field(default_factory=list)  # ... its T_world_camera (trajectory.tum)
    frames_outside_grid: list[int] = field(default_factory=list)  # frames fused with next to no reading in the grid

    def add_time(self, step: str, seconds: float) -> None:
        self.timing[step] = self.timing.get(step, 0.0) + seconds


@dataclass(frozen=True)
class _GridSpec:
    """Grid settings of a new volume; `volume(origin)` makes one."""

    size: float | tuple
    resolution: int | tuple | None  # 512 when voxel_size is None too
    voxel_size: float | None
    truncation: float | None  # None: volume.default_truncation of the voxel
    max_weight: int
    min_depth: float
    max_depth: float
    color: bool
    color_mode: str = "mean"

    def volume(self, origin) -> TernaryVolume:
        resolution = 512 if self.voxel_size is not None or self.resolution is None else self.resolution
        return TernaryVolume(size=self.size, resolution=resolution, voxel_size=self.voxel_size, origin=origin,
                             truncation=self.truncation, max_weight=self.max_weight, min_depth=self.min_depth,
                             max_depth=self.max_depth, color=self.color, color_mode=self.color_mode)


@dataclass
class DepthFilter:
    """Range limits, gap filling, bilateral and shadow / veil filters of each depth image; counts what it did."""

    min_depth: float
    max_depth: float
    fill_gaps: int
    bilateral: bool
    shadow_filter: bool
    shadow_baseline: float
    gap_pixels: int = 0
    drops: dict[str, int] = field(default_factory=dict)  # reason -> frames left without valid depth

    def __post_init__(self) -> None:
        check_number(self.fill_gaps, "fill_gaps", 0, 4096, integer=True)  # longer than any row: numba overflowed

    def __call__(self, frame: RGBDFrame) -> np.ndarray | None:
        """The filtered depth image, or None (counted) when no valid reading is left."""
        d = filters.range_filter(frame.depth, self.min_depth, self.max_depth)
        if self.fill_gaps:
            d, n = filters.fill_gaps(d, self.fill_gaps)
            self.gap_pixels += n
        if self.bilateral:
            d = filters.bilateral(d)
        if self.shadow_filter:
            d = filters.shadow_veil_filter(d, frame.K, baseline=self.shadow_baseline)
        if not np.any(d > 0):
            reason = f"no valid depth in [{self.min_depth}, {self.max_depth}] m after filtering"
            self.drops[reason] = self.drops.get(reason, 0) + 1
            return None
        return d


@dataclass(frozen=True)
class _PosePlan:
    mode: str  # forced, icp, hint or topic
    source: str  # iter_frames pose_source: tf, topic or none
    description: str
    world: str  # frame of the camera poses ("" when not known)
    warning: str = ""  # why TF poses were not taken though the recording has TF


def fuse_recording(recording: str | os.PathLike, *, size: float | tuple | str = "auto",
                   resolution: int | tuple | None = None, voxel_size: float | None = None, origin: tuple | None = None,
                   truncation: float | None = None,
                   max_weight: int = 128, min_depth: float = 0.3, max_depth: float = 4.0, color: bool = True,
                   pose: str | None = None, pose_topic: str | None = None, init: str | os.PathLike | None = None,
                   clear_spheres: Iterable[tuple] = (), clear_pois: str | os.PathLike | None = None,
                   start_s: float | None = None, end_s: float | None = None, every: int = 1,
                   tolerance_s: float = 0.05, fill_gaps: int = 2, bilateral: bool = False,
                   shadow_filter: bool = False, shadow_baseline: float = 0.08,
                   roles: Mapping[str, str | None] | None = None, quiet: bool = True,
                   argument_names: Mapping[str, str] | None = None, up=None, max_lost: float = 0.10,
                   max_memory: float | None = None, color_mode: str | None = None, icp: str = "projective",
                   photometric_weight: float = PHOTO_WEIGHT, check_only: bool = False) -> FusionResult | None:
    """Fuse the depth frames of `recording` (MCAP, ROS 1 .bag, ROS 2 bag folder) into a TernaryVolume.

    Grid: size (m, one or three values, or "auto": a box around what the selected frames observe from their poses,
    fusion.extent), resolution (voxels per axis: with a size 512 unless voxel_size, with "auto" over the box),
    voxel_size (m; with "auto" default 3 m / 512, coarser when the grid's worst case exceeds max_memory GiB, default
    half the available memory up to 2 GiB), origin (minimum corner; default centred on what the first frames see,
    with "auto" the box's corner), truncation (None: 3 cm, or 0.75 voxel over 4 cm voxels), max_weight,
    min_depth/max_depth (m), color. pose: forced (TF), icp, hint (ICP from TF) or topic (pose_topic); default forced
    when TF links the camera to the world, else icp. init: a volume.npz to continue. clear_spheres (x, y, z, r) and
    the POIs of clear_pois are forgotten (before fusing with init, else after). start_s / end_s (seconds from the
    recording start), every, tolerance_s: frame selection as io.frames.iter_frames. fill_gaps, bilateral,
    shadow_filter, shadow_baseline: depth filters. roles: detect_roles overrides. argument_names: how the report
    names the init, origin, clear_spheres, clear_pois, up and grid (GRID_ARGUMENTS) arguments (default these names;
    a command line passes its options). up: the world's direction against gravity (x, y, z); None decides it as
    fusion.up.choose_up says (the volume's up, stored in volume.npz, ternary.npz and the report with its source).
    max_lost: the largest share of tracked frames (icp, hint) that may be lost (not fused) before the run fails.
    color_mode: "mean" or "mode" (fusion/color_mode.py); None: the init volume's, else "mean". icp: the tracker's
    ICP, "projective" (fusion.icp) or "open3d" (tracking.ICP_METHODS). photometric_weight: projective ICP's colour
    term (fusion.photometric; 0: depth only). check_only: check the arguments as a run would, return None (kinfu
    batch's plan check)."""
    started = time.perf_counter()
    timing: dict[str, float] = {}
    names = {**{n: n for n in NAMED_ARGUMENTS}, **(argument_names or {})}
    up = None if up is None else check_up(up, "up")
    _check_arguments(pose, pose_topic, every, max_lost, size, start_s, end_s, photometric_weight)
    auto = isinstance(size, str)
    budget = budget_bytes(max_memory)
    spheres = _spheres(clear_spheres, clear_pois, names["clear_spheres"])
    wanted_mode = _wanted_color_mode(color_mode, color)
    grid_spec = _GridSpec(1.0 if auto else size, resolution, voxel_size, truncation, max_weight, min_depth,
                          max_depth, color, wanted_mode or "mean")
    depth_filter = DepthFilter(min_depth, max_depth, fill_gaps, bilateral, shadow_filter, shadow_baseline)
    vol, placement, grid_warnings = None, "", []
    if init:
        vol, placement, grid_warnings = _continue_init(init, wanted_mode, names, spheres, timing, dict(
            voxel_size=voxel_size, size=None if auto else size, resolution=resolution, origin=origin))
    else:
        grid_spec.volume(origin=origin or (0.0, 0.0, 0.0))  # refuse impossible grid settings before reading anything
    if check_only:
        return None

    with open_recording(recording) as rec:
        tf = TfBuffer.from_recording(rec)
        declared_up = read_world_up(rec)
        found = detect_roles(rec, tf=tf, **{k: v for k, v in (roles or {}).items() if v is not None})
        plan = _pose_plan(rec, tf, found, pose, pose_topic)
        if vol is not None and vol.frame and plan.world and vol.frame != plan.world:
            raise RecordingError(f"{init}: the volume was fused in frame {vol.frame!r}, but {rec.path} gives "
                                 f"camera poses in {plan.world!r}", parameter="init")
        warnings = rec.problems + ([plan.warning] if plan.warning else []) + grid_warnings + poi_frame_warnings(
            clear_pois, plan.world or (vol.frame if vol is not None else ""), names["clear_pois"])
        sizing, notes = ({"mode": "init", "init": str(init)} if init else {"mode": "given"}), []
        if auto and vol is None:
            t0 = time.perf_counter()
            chosen = _auto_grid(rec, found, plan, grid_spec, resolution, voxel_size, origin, budget,
                                dict(pose_topic=pose_topic, start_s=start_s, end_s=end_s, every=every, tf=tf,
                                     tolerance_s=tolerance_s))
            timing["size"] = time.perf_counter() - t0
            grid_spec, origin, sizing = _apply_auto_grid(chosen, grid_spec, origin, names, notes, warnings)
        stats = FrameStats()
        frames = iter_frames(rec, found, pose_source=plan.source, pose_topic=pose_topic, start_s=start_s,
                             end_s=end_s, every=every, stats=stats, tf=tf, tolerance_s=tolerance_s)
        integrator = _Integrator(vol, plan, grid_spec, origin, names["origin"], str(rec.path), timing, icp,
                                 photometric_weight)
        # past max_lost of the most frames the time window can select (counted before reading, when tracking): stop
        bound = (-(-window_depth_count(rec, found.depth_topic, start_s, end_s, tolerance_s) // every)
                 if integrator.tracker is not None else 0)
        for frame in progress(_timed(frames, timing, "read"), desc="fusing", quiet=quiet, unit="frame"):
            t0 = time.perf_counter()
            d = depth_filter(frame)
            _add(timing, "filter", time.perf_counter() - t0)
            if d is not None:
                integrator.add(frame, d)
                if len(integrator.lost) > max_lost * bound:
                    _tracking_verdict(integrator, max_lost, str(rec.path), bound)
        integrator.finish()
        if integrator.used == 0:
            dropped = {**stats.dropped, **depth_filter.drops}
            why = "; ".join(f"{k}: {v}" for k, v in dropped.items()) or "no depth frames in the selection"
            raise RecordingError(f"{rec.path}: no usable depth frames ({why})")
        warnings += _frames_warnings(stats, integrator, max_lost, str(rec.path), depth_filter)
        vol = integrator.volume
        vol.frame = vol.frame or plan.world

    if not init:
        _clear_spheres(vol, spheres)
    warnings += _sphere_warnings(vol, spheres, clear_pois)
    t0 = time.perf_counter()
    grid, counts, bounding_box, mesh, cloud = _read_out(vol)
    _add(timing, "extract", time.perf_counter() - t0)
    t0 = time.perf_counter()
    up_choice = _decide_up(vol, grid, cloud, integrator, up, bool(init), declared_up, plan, names["up"])
    warnings += up_choice.warnings
    _add(timing, "up", time.perf_counter() - t0)
    faces = face_contacts(grid.labels)
    warnings += _face_warnings(faces, vol.voxel_size)
    return FusionResult(
        recording=str(rec.path), roles=found, pose_mode=plan.mode, pose_source=plan.description, volume=vol,
        placement=placement or integrator.placement, frame_stats=stats, frames_used=integrator.used,
        frames_outside_grid=integrator.outside_grid, dropped=_dropped(stats, depth_filter, integrator),
        tracking=integrator.track_log if integrator.tracker is not None else None,
        depth_filter=depth_filter, every=every, start_s=start_s, end_s=end_s, cleared_spheres=spheres,
        warnings=warnings, grid=grid, counts=counts, bounding_box=bounding_box, mesh=mesh, cloud=cloud,
        timing=timing, started=started, up=up_choice.to_json(), grid_sizing=sizing, face_contacts=faces,
        notes=notes, camera_stamps_ns=integrator.camera_stamps_ns, camera_poses=integrator.camera_poses)


def _continue_init(init, wanted_mode: str | None, names: dict, spheres: list[dict], timing: dict,
                   grid_given: dict) -> tuple[TernaryVolume, str, list[str]]:
    """The init volume to fuse on (its spheres cleared first), how the report names its placement, and the warnings
    for grid arguments given that differ from its grid (grid_given: voxel_size, size, resolution, origin)."""
    t0 = time.perf_counter()
    vol = _load_init(init, wanted_mode)
    timing["load_init"] = time.perf_counter() - t0
    warnings = _init_grid_warnings(vol, grid_given, names, init)
    _clear_spheres(vol, spheres)
    return vol, f"{names['init']} {init}", warnings


def _clear_spheres(vol: TernaryVolume, spheres: list[dict]) -> None:
    for s in spheres:
        vol.clear_sphere(s["center"], s["radius"])


#: the grid arguments an init volume's own grid overrides, and what each is of that grid
GRID_ARGUMENTS = {"voxel_size": ("voxel size", " m"), "size": ("size", " m"), "resolution": ("resolution", " voxels"),
                  "origin": ("origin", " m")}
#: the arguments messages name as argument_names says (a command line: by its options)
NAMED_ARGUMENTS = ("init", "clear_spheres", "clear_pois", "up", *GRID_ARGUMENTS)


def _init_grid_warnings(vol: TernaryVolume, given: Mapping, names: Mapping[str, str], init) -> list[str]:
    """The grid arguments given with init (not None) that differ from the init volume's grid: its grid wins, and
    the run says so rather than fusing on another grid than the one asked for without a word."""
    voxel, shape = vol.voxel_size, vol.shape
    # the same grid: a voxel size and origin as printed (6 digits), a size within a voxel (sizes are rounded up)
    grid = {"voxel_size": (voxel, voxel * 1e-5), "size": (tuple(n * voxel for n in shape), voxel),
            "resolution": (shape, 0.5), "origin": (tuple(float(v) for v in vol.origin), voxel * 1e-3)}
    out = []
    for name, value in given.items():
        actual, tolerance = grid[name]
        if value is not None and np.any(np.abs(np.asarray(value, dtype=float) - np.asarray(actual)) > tolerance):
            what, unit = GRID_ARGUMENTS[name]
            out.append(f"{names[name]} {_values(value)} differs from the {what} of the {names['init']} volume {init} "
                       f"({_values(actual)}{unit}); its grid wins: {names[name]} is ignored")
    return out


def _values(value) -> str:
    return ",".join(f"{float(v):.6g}" for v in np.atleast_1d(np.asarray(value, dtype=float)))


def _wanted_color_mode(color_mode: str | None, color: bool) -> str | None:
    mode = None if color_mode is None else check_color_mode(color_mode)
    if mode == "mode" and not color:
        raise ConfigError("the colour mode filter needs colour; it cannot go with color off", parameter="color_mode")
    return mode


def _load_init(init, wanted_mode: str | None) -> TernaryVolume:
    """The volume to continue; it goes on in the colour mode it was fused with: asking for the other one is an
    error."""
    vol = load_volume(init)
    if vol.truncation < MIN_TRUNCATION_VOXELS * vol.voxel_size:  # read back as fused; fusing on would lose surfaces
        raise VolumeError(f"{init}: its truncation {vol.truncation:g} m is under half its {vol.voxel_size:g} m voxel: "
                          f"fused into, surfaces would fall between voxel centres and vanish (not a volume kinfu "
                          f"fused)")
    if wanted_mode is not None and vol.color and wanted_mode != vol.color_mode:
        raise ConfigError(f"{init}: the volume was fused with colour mode {vol.color_mode!r}, not "
                          f"{wanted_mode!r}; continue it with its own", parameter="color_mode")
    return vol


def _check_arguments(pose: str | None, pose_topic: str | None, every: int, max_lost: float, size,
                     start_s: float | None = None, end_s: float | None = None,
                     photometric_weight: float = PHOTO_WEIGHT) -> None:
    """ConfigError naming the first argument of fuse_recording out of its range, before anything is read."""
    check_window(start_s, end_s)
    check_number(photometric_weight, "photometric_weight", 0.0, MAX_PHOTO_WEIGHT)
    if pose is not None and pose not in POSE_MODES:
        raise ConfigError(f"expected one of {', '.join(POSE_MODES)}, got {pose!r}", parameter="pose")
    if pose == "topic" and not pose_topic:
        raise ConfigError("needed with pose 'topic' (a PoseStamped/Odometry topic)", parameter="pose_topic")
    if every < 1:
        raise ConfigError(f"expected an integer >= 1, got {every}", parameter="every")
    if not 0 <= max_lost <= 1:
        raise ConfigError(f"expected a share of the tracked frames in [0, 1], got {max_lost}", parameter="max_lost")
    if isinstance(size, str) and size != "auto":
        raise ConfigError(f"expected metres or 'auto', got {size!r}", parameter="size")


def _dropped(stats: FrameStats, depth_filter: DepthFilter, integrator: "_Integrator") -> dict[str, int]:
    """Frames dropped by reason: while assembling, by the depth filter, and lost by tracking."""
    dropped = dict(stats.dropped)
    for reason, n in depth_filter.drops.items():
        dropped[reason] = dropped.get(reason, 0) + n
    if integrator.lost:
        dropped[DROP_LOST] = len(integrator.lost)
    return dropped


def _apply_auto_grid(chosen: AutoGrid, grid_spec: "_GridSpec", origin, names: dict, notes: list[str],
                     warnings: list[str]) -> tuple["_GridSpec", tuple, dict]:
    """The grid settings of an automatic size (and the note and warning it gives): spec, origin, sizing."""
    grid_spec = replace(grid_spec, size=chosen.size, resolution=None, voxel_size=chosen.voxel_size)
    if origin is None:
        names["origin"] = f"size auto (the box of what {chosen.frames} frame(s) observe)"
    notes.append(chosen.note())
    if chosen.capped.startswith("box cropped"):
        warnings.append(f"size auto: {chosen.capped}; the scene goes on beyond the grid")
    return grid_spec, tuple(chosen.origin), chosen.as_dict()


def _decide_up(vol: TernaryVolume, grid: TernaryGrid, cloud, integrator: "_Integrator", up, continued: bool,
               declared_up, plan: "_PosePlan", up_name: str):
    """Decide the world's up once (fusion.up.choose_up) and store it, with the depth intrinsics, on the volume
    and its grid; returns the choice (its warnings and report entry)."""
    choice = choose_up(option=up, init_up=vol.up if continued else None, init_source=vol.up_source,
                       declared=declared_up, world=plan.world, world_from_tf=plan.source in ("tf", "topic"),
                       points=np.asarray(cloud.points), normals=np.asarray(cloud.normals),
                       camera_poses=np.array(integrator.camera_poses), up_name=up_name)
    vol.up = grid.up = choice.up
    vol.up_source = choice.source if choice.up is not None else ""
    vol.intrinsics = vol.intrinsics or integrator.intrinsics
    return choice


def _auto_grid(rec: Recording, roles: Roles, plan: _PosePlan, grid_spec: _GridSpec, resolution, voxel_size,
               origin, budget: int, selection: dict) -> AutoGrid:
    """Size 'auto': survey up to SURVEY_FRAMES of the selected frames (depth only, evenly spread) at their poses;
    without poses (icp with no TF) the first frame at the identity, its box grown by ICP_GROW."""
    count = rec.topics[roles.depth_topic].count if roles.depth_topic in rec.topics else 0
    step = max(1, -(-count // (selection["every"] * SURVEY_FRAMES)))
    read = [0]  # frames iter_frames gave, with a pose or not
    stats = FrameStats()  # why frames were dropped, for the error when none is left

    def frames_read():
        for f in iter_frames(rec, replace(roles, color_topic=None), pose_source=plan.source, stats=stats,
                             **{**selection, "every": selection["every"] * step}):
            read[0] += 1
            yield f
    frames = frames_read()
    lo, hi = grid_spec.min_depth, grid_spec.max_depth
    readings = [np.inf, 0.0]  # the nearest and farthest reading of the frames surveyed (0 = none)

    def in_range(depth: np.ndarray) -> np.ndarray:
        valid = depth[depth > 0]
        if valid.size:
            readings[0], readings[1] = min(readings[0], float(valid.min())), max(readings[1], float(valid.max()))
        return filters.range_filter(depth, lo, hi)
    if plan.source == "none":
        first = next(iter(frames), None)
        views = [] if first is None else [(in_range(first.depth), first.K, np.eye(4))]
        grow = ICP_GROW
    else:
        views = ((in_range(f.depth), f.K, f.T_world_camera) for f in frames
                 if f.T_world_camera is not None and np.all(np.isfinite(f.T_world_camera)))
        grow = 0.0
    seen = survey(views, lo, hi)
    if seen.frames == 0:  # not "no valid depth": there was no frame to look at, or none had a pose
        if not read[0]:
            why = "; ".join(f"{k}: {v}" for k, v in stats.dropped.items()) or "no depth frames in the selection"
            looked = f", of every {step}th selected frame looked at to size the grid" if step > 1 and stats.dropped else ""
            raise RecordingError(f"{rec.path}: no usable depth frames ({why}{looked})")
        raise RecordingError(f"{rec.path}: no selected depth frame has a camera pose in {plan.world or 'the world'}"
                             f" frame, so the grid cannot be sized around them")
    if len(seen.points) == 0 and readings[1] > 0:  # readings, none in range: say which, not "give the size"
        units = ("; 32FC1 depth is in metres: millimetres stored as metres?"
                 if readings[0] >= MAX_16BIT_MM / 1000 else "")  # as FrameStats' warning reads them
        raise RecordingError(f"{rec.path}: no depth reading of the {seen.frames} frames looked at to size the grid "
                             f"lies in the depth range [{lo:g}, {hi:g}] m (readings from {readings[0]:.3g} to "
                             f"{readings[1]:.3g} m{units})")
    return auto_grid(seen, voxel_size=voxel_size, resolution=resolution,
                     truncation=grid_spec.truncation or DEFAULT_TRUNCATION_M, budget=budget, origin=origin, grow=grow,
                     color="mode" if grid_spec.color and grid_spec.color_mode == "mode" else grid_spec.color)


# more than this share of the depth frames without a camera pose (outside the TF or pose topic's time, a chain that
# breaks) is a warning: a few at the ends are usual (TF starts after the camera), a share of the scene is not
NO_POSE_WARN = 0.10
# likewise for frames without a valid depth reading: a few empty images are a sensor's hiccups, a share of them not
NO_DEPTH_WARN = 0.10


def _frames_warnings(stats: FrameStats, integrator: "_Integrator", max_lost: float, recording: str,
                     depth_filter: DepthFilter) -> list[str]:
    """What the frames read and fused leave in doubt: the readers' warnings, frames without a camera pose or
    without valid depth, frames tracking lost (RecordingError past max_lost), tracked poses that look wrong, frames
    fused at their TF pose, frames fused with (almost) none of their readings in the grid."""
    return (stats.warnings(recording) + _pose_drop_warnings(stats, recording)
            + _empty_depth_warnings(stats, depth_filter, recording)
            + _tracking_verdict(integrator, max_lost, recording) + _tracking_doubts(integrator.track_log)
            + _fallback_warnings(integrator.track_log, max_lost) + _outside_grid_warnings(integrator, recording)
            + _narrow_frame_warnings(integrator, recording) + _pose_jump_warnings(integrator, recording))


def _pose_drop_warnings(stats: FrameStats, recording: str) -> list[str]:
    """A warning when more than NO_POSE_WARN of the selected depth frames (those `every` kept) were not fused for
    want of a camera pose (they were counted in the report only, and the volume lacked what they saw)."""
    counts = {r: stats.dropped.get(r, 0) for r in (DROP_NO_POSE, DROP_CHAIN_BROKEN, DROP_NO_POSE_TOPIC)}
    return _drop_share_warnings(counts, stats, NO_POSE_WARN, recording, "have no camera pose",
                                "the volume lacks what they saw")


def _empty_depth_warnings(stats: FrameStats, depth_filter: DepthFilter, recording: str) -> list[str]:
    """A warning when more than NO_DEPTH_WARN of the selected depth frames were not fused for want of a valid depth
    reading (an empty image, or none left by the range and filters): as for missing poses, the volume lacks what
    they should have seen, and a sensor that sends empty images half the time is worth knowing about."""
    counts = {DROP_EMPTY: stats.dropped.get(DROP_EMPTY, 0), **depth_filter.drops}
    return _drop_share_warnings(counts, stats, NO_DEPTH_WARN, recording, "have no valid depth reading",
                                "the volume lacks what they should have seen (check the sensor, the depth units, "
                                "min_depth/max_depth)")


def _drop_share_warnings(counts: dict[str, int], stats: FrameStats, share: float, recording: str, lack: str,
                         consequence: str) -> list[str]:
    """One warning when the frames dropped for the reasons counted are more than `share` of the depth frames
    selected (those `every` kept), naming each reason's count."""
    counts = {r: c for r, c in counts.items() if c}
    n, selected = sum(counts.values()), stats.depth_messages - stats.skipped
    if n <= share * max(selected, 1):
        return []
    why = "; ".join(f"{r}: {c}" for r, c in counts.items())
    return [f"{recording}: {n} of the {selected} depth frames selected {lack} ({why}) and were not fused: "
            f"{consequence}"]


def _outside_grid_warnings(integrator: "_Integrator", recording: str) -> list[str]:
    """A warning naming the frames fused with under IN_GRID_MIN_SHARE of their readings inside the grid: counted
    as used, they added no surface (a camera pose that jumps away, or a grid that leaves out what they saw)."""
    out = integrator.outside_grid
    if not out:
        return []
    shown = ", ".join(str(i) for i in out[:10]) + (", ..." if len(out) > 10 else "")
    return [f"{recording}: {len(out)} of the {integrator.used} frames fused have under {100 * IN_GRID_MIN_SHARE:g} % "
            f"of their depth readings inside the grid, so they added next to no surface to it (frames {shown}; "
            f"report.json frames.outside_grid): a wrong camera pose (a TF that jumps) or a grid that leaves out what "
            f"they saw"]


# given camera poses (TF, a pose topic) moving faster than this between two fused frames jump (a TF glitch, a
# re-localised map -> odom, wrong stamps): the scene is fused twice, displaced, and an auto-sized grid grows to hold
# both copies (a 5 m jump of 3 frames: a 9.3 m grid, no other warning). KinFu's per-frame ICP limit as a speed (0.1 m
# a frame at 30 Hz); hand-held 7-Scenes frames move up to 1.3 m/s
JUMP_SPEED_M_S = MAX_SPEED_M_S
JUMP_MIN_M = 0.05  # ... and farther than this (near frames with jittery stamps are no jump)


def _pose_jump_warnings(integrator: "_Integrator", recording: str) -> list[str]:
    """A warning naming the fused frames whose given pose moved over JUMP_SPEED_M_S (and JUMP_MIN_M) since the
    frame fused before (poses taken as given: forced or topic mode; tracking has its own speed check)."""
    if integrator.mode not in ("forced", "topic") or len(integrator.camera_poses) < 2:
        return []
    step = np.linalg.norm(np.diff([np.asarray(T)[:3, 3] for T in integrator.camera_poses], axis=0), axis=1)
    dt = np.diff(np.asarray(integrator.camera_stamps_ns, dtype=np.int64)) * 1e-9
    jump = (step > JUMP_MIN_M) & (step > JUMP_SPEED_M_S * np.maximum(dt, 0.0))
    if not jump.any():
        return []
    at = np.flatnonzero(jump)
    k = int(at[np.argmax(step[at])])
    frames = [integrator.camera_frames[i + 1] for i in at]
    shown = ", ".join(map(str, frames[:10])) + (", ..." if len(frames) > 10 else "")
    return [f"{recording}: the given camera poses jump at {len(frames)} fused frame(s) ({shown}; the largest "
            f"{step[k]:.2f} m in {max(dt[k], 0.0):.3f} s, faster than {JUMP_SPEED_M_S:g} m/s): a TF glitch, a "
            f"re-localisation or wrong stamps fuse the scene twice, displaced (check the poses, or refine them by "
            f"ICP: pose mode hint)"]


def _narrow_frame_warnings(integrator: "_Integrator", recording: str) -> list[str]:
    """A warning when ICP tracked depth frames narrower than MIN_TRACKING_WIDTH: their poses may drift by
    centimetres with every frame passing the loss checks."""
    size = integrator.intrinsics
    if integrator.tracker is None or not integrator.track_log or size is None or size["width"] >= MIN_TRACKING_WIDTH:
        return []
    return [f"{recording}: ICP tracked {size['width']}x{size['height']} px depth frames, narrower than "
            f"{MIN_TRACKING_WIDTH} px: so few pixels pin the camera pose down poorly (on identical frames the tracked "
            f"camera drifted centimetres with no frame failing a check); given camera poses (TF or a pose topic) "
            f"serve better"]


def _tracking_verdict(integrator: _Integrator, max_lost: float, recording: str,
                      bound: int | None = None) -> list[str]:
    """Warnings about frames lost by tracking; RecordingError when more than max_lost of the tracked frames were,
    or (while fusing) of `bound`, the most frames the selection can have. When tracking ran only because TF does
    not reach the camera (integrator.no_tf_link), a run that fails names that cause, not max_lost."""
    lost, tracked = integrator.lost, len(integrator.track_log)
    if not lost:
        return []
    shown = ", ".join(str(i) for i in lost[:10]) + (", ..." if len(lost) > 10 else "")
    what = (f"tracking ({integrator.mode}) lost {len(lost)} of {tracked} tracked frames "
            f"({100 * len(lost) / tracked:.0f} %): frames {shown}")
    # hint mode loses only frames ICP put far from their TF poses (tracking check 5; the others fall back to the TF
    # pose): the TF itself is suspect (a wrong camera frame, a broken link)
    advice = "sub-sample less, or give camera poses"
    if integrator.mode == "hint":
        advice = "ICP put frames far from their TF poses: check the camera frame and the TF chain to it"
    parameter: str | None = "max_lost"
    if integrator.no_tf_link:  # tracking only because TF did not reach the camera: the missing link is what to mend
        advice, parameter = integrator.no_tf_link.removeprefix(f"{recording}: "), None
    if bound is not None:
        raise RecordingError(f"{recording}: {what}; stopped: more than {100 * max_lost:.0f} % of the {bound} frames "
                             f"selected ({advice})", parameter=parameter)
    if len(lost) > max_lost * tracked:
        raise RecordingError(f"{recording}: {what}; more than the {100 * max_lost:.0f} % allowed ({advice})",
                             parameter=parameter)
    return [f"{what}; they were not fused"]


def ate_vs_given(track_log: list[dict]) -> dict | None:
    """The tracked frames' camera positions against the recording's own poses (`given_minus_tracked_m` of the
    frames ICP placed: neither lost nor fused at their TF pose): RMSE, max (m), frames and the frame of the max; None
    without given poses."""
    dev = [(t["given_minus_tracked_m"], t["index"]) for t in track_log
           if not t["lost"] and not t.get("tf_fallback") and t.get("given_minus_tracked_m") is not None]
    if not dev:
        return None
    d = np.array([v for v, _ in dev])
    return {"rmse": round(float(np.sqrt(np.mean(d ** 2))), 5), "max": round(float(d.max()), 5), "frames": len(d),
            "max_frame": dev[int(np.argmax(d))][1]}


def _tracking_doubts(track_log: list[dict]) -> list[str]:
    """Warnings when tracked poses look wrong although no frame was lost: far from the recording's own camera
    poses, or found mostly by the re-localisation search (the first ICP attempt failed). Both come with the
    tracked camera's median motion per frame, since frame-to-model ICP assumes small steps."""
    kept = [t for t in track_log if not t["lost"] and not t.get("tf_fallback")]
    if not kept:
        return []
    T = np.array([t["T_world_camera"] for t in kept], dtype=np.float64)
    step = ""
    if len(T) > 1:
        move = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
        cos = (np.einsum("nij,nij->n", T[1:, :3, :3], T[:-1, :3, :3]) - 1.0) / 2.0
        turn = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        step = f"; the tracked camera moves a median {100 * np.median(move):.1f} cm / {np.median(turn):.1f} deg per frame"
    out = []
    ate = ate_vs_given(track_log)
    if ate is not None and ate["rmse"] > DRIFT_WARN_M:
        out.append(f"tracked camera poses lie {100 * ate['rmse']:.1f} cm RMS from the recording's own poses (max "
                   f"{100 * ate['max']:.1f} cm at frame {ate['max_frame']}): tracking drifted or the camera moves "
                   f"too fast for frame-to-model ICP{step}; the recorded poses (pose 'forced') may serve better")
        step = ""
    reloc = sum(bool(t.get("relocalised")) for t in kept)
    if reloc > RELOCALISED_WARN * len(kept):
        out.append(f"{reloc} of {len(kept)} tracked frames were found only by the wider re-localisation search (the "
                   f"first ICP attempt failed): their poses are uncertain{step}")
    return out


def _fallback_warnings(track_log: list[dict], max_lost: float) -> list[str]:
    """Hint mode: a warning when ICP refined too few frames (more than max_lost of them fused at their TF pose),
    with why ICP failed on them, counted."""
    fell = [t for t in track_log if t.get("tf_fallback")]
    if not fell or len(fell) <= max_lost * len(track_log):
        return []
    why: dict[str, int] = {}
    for t in fell:
        key = LOSS_CHECKS.get(t.get("check", ""), "only re-localisation found a pose")
        why[key] = why.get(key, 0) + 1
    reasons = ", ".join(f"{k}: {n}" for k, n in sorted(why.items(), key=lambda kv: -kv[1]))
    return [f"ICP refined the TF pose of only {len(track_log) - len(fell)} of {len(track_log)} tracked frames; "
            f"{len(fell)} were fused at their TF pose ({reasons}; report.json "
            f"tracking.tf_fallback_frames)"]


def _face_warnings(faces: dict[str, int], voxel_size: float) -> list[str]:
    """A warning when the grid cuts the scene; a few speckle voxels on a face are only counted (face_contacts)."""
    touched = cut_faces(faces, voxel_size)
    if not touched:
        return []
    where = ", ".join(f"{f} ({n})" for f, n in touched.items())
    return [f"occupied voxels touch the grid faces {where}: the scene goes on beyond the grid (a larger grid "
            f"would keep it)"]


def _spheres(clear_spheres: Iterable[tuple], clear_pois: str | os.PathLike | None, spheres_name: str) -> list[dict]:
    """The spheres to forget, checked: each given (x, y, z, r), then one per POI of the clear_pois file."""
    out = []
    for s in clear_spheres:
        s = tuple(float(v) for v in s)
        if len(s) != 4 or not all(np.isfinite(s)) or s[3] <= 0 or max(abs(v) for v in s) > MAX_COORDINATE_M:
            raise ConfigError(f"expected x,y,z,r with r > 0, all within {MAX_COORDINATE_M:g} m, got {s}",
                              parameter="clear_spheres")
        out.append({"center": list(s[:3]), "radius": s[3], "source": spheres_name})
    if clear_pois:
        for p in read_pois(clear_pois):
            if not (np.isfinite(p.radius) and p.radius > 0):
                raise ConfigError(f"{clear_pois}: POI {p.id} has radius {p.radius}, expected > 0")
            out.append({"center": [float(v) for v in p.position], "radius": float(p.radius),
                        "source": f"{clear_pois}#{p.id}"})
    return out


def _sphere_warnings(vol: TernaryVolume, spheres: list[dict], clear_pois) -> list[str]:
    """A sphere to forget that misses the grid forgot nothing (POIs of another scene, or in another frame's
    coordinates), and a POI file without POIs asks for nothing: said, not passed over."""
    lo, hi = vol.bounds()
    out = [f"{s['source']}: the sphere to forget at ({', '.join(f'{v:.3g}' for v in s['center'])}) m, radius "
           f"{s['radius']:.3g} m, lies outside the grid [{', '.join(f'{v:.3g}' for v in lo)}] - "
           f"[{', '.join(f'{v:.3g}' for v in hi)}] m: nothing was forgotten there"
           for s in spheres
           if np.linalg.norm(np.clip(s["center"], lo, hi) - np.asarray(s["center"])) >= s["radius"]]
    if clear_pois and not any(s["source"].startswith(f"{clear_pois}#") for s in spheres):
        out.append(f"{clear_pois}: holds no POI, so nothing was forgotten")
    return out


def _pose_plan(rec: Recording, tf: TfBuffer, roles: Roles, pose: str | None, pose_topic: str | None) -> _PosePlan:
    """Pose mode (the requested one, else topic when pose_topic is given, forced when TF links camera and world,
    else icp) and its source."""
    world_frame, camera_frame = roles.world_frame, roles.camera_frame
    # both frames named exactly as in the TF tree, and linked by a chain of transforms
    has_tf = bool(world_frame and camera_frame and {world_frame, camera_frame} <= set(tf.frames())
                  and tf.connected(world_frame, camera_frame))
    mode = pose or ("topic" if pose_topic else "forced" if has_tf else "icp")  # a pose topic given is meant to be used
    if pose_topic and mode != "topic":
        raise ConfigError(f"a pose topic is read only in pose mode 'topic', not {mode!r}", parameter="pose_topic")
    camera = camera_frame or "? (the depth images carry no frame_id)"
    if mode in ("forced", "hint") and not has_tf:
        raise RecordingError(f"{rec.path}: pose mode {mode!r} needs TF from {world_frame or 'a world frame'} to "
                             f"camera frame {camera} (use pose mode 'icp' or 'topic', or name the camera and world "
                             f"frames)", parameter="pose")
    if mode == "topic":
        source, description = "topic", f"topic {pose_topic}"
    elif mode == "icp" and not has_tf:
        source, description = "none", "none (first camera pose = world origin)"
    else:
        source, description = "tf", f"tf {world_frame} <- {camera_frame}"
        if mode == "icp":
            description += " (first frame only)"
    warning = ""
    if pose is None and not has_tf and tf.frames():  # TF there, but not to the camera: say so, ICP may drift
        warning = (f"{rec.path}: the TF tree ({len(tf.frames())} frames) does not link camera frame "
                   f"{camera} to {world_frame or 'a world frame'}: camera poses come from ICP "
                   f"tracking instead (name the frames, or pose mode 'forced' to make a missing link an error)")
    elif mode in ("forced", "hint") and camera_frame == world_frame:  # a frame in itself: every pose the identity
        warning = (f"{rec.path}: the camera frame is the world frame {world_frame!r}: every depth frame is fused at "
                   f"the identity pose (a camera that never moves; name the camera frame if the depth images' "
                   f"frame_id is wrong)")
    return _PosePlan(mode, source, description, _world_frame(rec, source, roles, pose_topic), warning)


def _world_frame(rec: Recording, source: str, roles: Roles, pose_topic: str | None) -> str:
    """Name of the frame the camera poses of this run are in ("" when not known: ICP from an unnamed first pose,
    or a pose topic without frame_id)."""
    if source == "tf":
        return roles.world_frame or ""
    if source == "topic":
        rec.require_topic(pose_topic, "pose topic")
        msg = rec.first_message(pose_topic)
        return header_frame(msg).lstrip("/") if msg is not None else ""
    return ""


class _Integrator:
    """Integrates filtered frames into the volume: creates it on the first frames when there is none yet,
    takes each camera pose as given or tracks it (icp from the previous pose, hint from the given one)."""

    def __init__(self, volume: TernaryVolume | None, plan: _PosePlan, grid_spec: _GridSpec, origin: tuple | None,
                 origin_name: str, recording: str, timing: dict[str, float], icp: str = "projective",
                 photometric_weight: float = PHOTO_WEIGHT) -> None:
        self.volume = volume
        self.mode = mode = plan.mode
        self.no_tf_link = plan.warning if plan.source != "tf" else ""  # why ICP tracks though the recording has TF
        self.grid_spec = grid_spec
        self.origin = origin
        self.origin_name = origin_name
        self.recording = recording
        self.timing = timing
        self.tracker = FrameToModelTracker(icp=icp, init_is_hint=mode == "hint", photo_weight=photometric_weight) \
            if mode in ("icp", "hint") else None
        self.track_log: list[dict] = []
        self.lost: list[int] = []  # indices of the frames tracking lost (not fused)
        self.tf_fallback: list[int] = []  # hint mode: frames ICP could not refine, fused at their TF pose
        self.placement = ""
        self.used = 0
        self.prev_T: np.ndarray | None = None  # the last good pose and its stamp; the one before (velocity)
        self.prev_stamp: int | None = None
        self.prev2: tuple[np.ndarray, int] | None = None
        self.prev_given: np.ndarray | None = None  # the given pose of the last good frame (hint)
        self.buffered: list[tuple[RGBDFrame, np.ndarray]] = []  # frames waiting for the grid to be placed
        self.n_place = 1 if mode == "icp" else PLACEMENT_FRAMES
        self.camera_poses: list[np.ndarray] = []  # T_world_camera of every frame integrated (fusion.up)
        self.camera_stamps_ns: list[int] = []  # and its stamp
        self.camera_frames: list[int] = []  # and its frame index
        self.intrinsics: dict | None = None  # of the first frame integrated
        self.outside_grid: list[int] = []  # frames fused with under IN_GRID_MIN_SHARE of their readings in the grid

    def add(self, frame: RGBDFrame, depth: np.ndarray) -> None:
        if self.volume is not None:
            self._integrate(frame, depth)
            return
        self.buffered.append((frame, depth))
        if len(self.buffered) >= self.n_place:
            self._place()

    def finish(self) -> None:
        """Place the grid on the frames buffered so far when fewer than n_place came."""
        if self.volume is None and self.buffered:
            self._place()

    def _place(self) -> None:
        """Create the volume (at the given origin, else centred on the buffered frames' back-projected depth) and
        integrate the buffered frames."""
        if self.origin is not None:
            self.volume, self.placement = self.grid_spec.volume(self.origin), self.origin_name
        else:
            views = []
            for f, d in self.buffered:
                T = f.T_world_camera
                if self.mode == "icp" and T is None:
                    T = np.eye(4)
                if T is None or not np.all(np.isfinite(T)):
                    continue
                views.append((d, f.K, T))
            probe = self.grid_spec.volume((0.0, 0.0, 0.0))
            size = np.array(probe.shape) * probe.voxel_size
            self.volume = self.grid_spec.volume(default_origin(views, size))
            self.placement = f"centred on the first {len(views)} frame(s)"
        for f, d in self.buffered:
            self._integrate(f, d)
        self.buffered = []

    def _integrate(self, frame: RGBDFrame, depth: np.ndarray) -> None:
        vol = self.volume
        where = f"{self.recording}: frame {frame.index} (stamp {frame.stamp_ns} ns)"
        T_given = frame.T_world_camera
        if T_given is not None and not np.all(np.isfinite(T_given)):
            raise VolumeError(f"{where}: camera pose is not finite (NaN or inf)")
        if self.mode in ("forced", "topic"):
            T = T_given
        elif self.prev_T is None and (self.mode == "icp" or vol.frames_integrated == 0):
            # the first frame anchors the model: its given pose (identity when icp has none)
            T = T_given if T_given is not None or self.mode == "hint" else np.eye(4)
        else:  # icp tracks from the previous pose, hint from the given one
            t0 = time.perf_counter()
            dt = None if self.prev_stamp is None else (frame.stamp_ns - self.prev_stamp) * 1e-9
            candidates = self._candidates(T_given, dt)
            res = self.tracker.track(vol, depth, frame.K, candidates, T_ref=self.prev_T, dt_s=dt, color=frame.color,
                                     color_mask=frame.color_mask)
            _add(self.timing, "track", time.perf_counter() - t0)
            fallback = T_given if self.mode == "hint" and _hint_falls_back(res) else None
            self.track_log.append(_track_entry(frame, res, T_given, fallback))
            if fallback is not None:
                self.tf_fallback.append(frame.index)
            elif res.lost:  # not fused at a stale pose: the next frame is tracked from the last good one
                self.lost.append(frame.index)
                return
            T = res.T_world_camera if fallback is None else fallback
        t0 = time.perf_counter()
        try:
            fused = vol.integrate(depth, frame.K, T, frame.color, frame.color_mask)
        except VolumeError as exc:
            raise VolumeError(f"{where}: {exc}") from None
        _add(self.timing, "integrate", time.perf_counter() - t0)
        if self.tracker is not None:  # the next frame's photometric reference (a no-op without colour)
            t0 = time.perf_counter()
            self.tracker.keep_reference(vol, depth, frame.K, T, frame.color, frame.color_mask)
            _add(self.timing, "track", time.perf_counter() - t0)
        if fused["readings_in_grid"] < IN_GRID_MIN_SHARE * fused["readings"]:
            self.outside_grid.append(frame.index)
        if self.prev_T is not None and self.prev_stamp is not None:
            self.prev2 = (self.prev_T, self.prev_stamp)
        self.prev_T, self.prev_stamp = np.asarray(T, dtype=np.float64), frame.stamp_ns
        self.prev_given = T_given
        self.used += 1
        self.camera_poses.append(self.prev_T)
        self.camera_stamps_ns.append(int(frame.stamp_ns))
        self.camera_frames.append(frame.index)
        if self.intrinsics is None:
            K = np.asarray(frame.K, dtype=np.float64)
            self.intrinsics = {"fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]),
                               "cy": float(K[1, 2]), "width": int(depth.shape[1]), "height": int(depth.shape[0])}

    def _candidates(self, T_given: np.ndarray | None, dt: float | None) -> list[np.ndarray]:
        """Initial poses for the tracker, the first tried first: icp the constant-velocity prediction, then the
        last good pose; hint the given pose, then the last good pose moved by the given poses' motion since."""
        if self.mode == "hint":
            out = [T_given]
            if self.prev_T is not None and self.prev_given is not None:
                out.append(self.prev_T @ np.linalg.inv(self.prev_given) @ T_given)
            return out
        prev2_T, dt_prev = (None, None) if self.prev2 is None else (
            self.prev2[0], (self.prev_stamp - self.prev2[1]) * 1e-9)
        pred = predict_pose(self.prev_T, prev2_T, dt_prev, dt)
        return [pred, self.prev_T] if not np.allclose(pred, self.prev_T) else [pred]


@dataclass
class TrackedFrames:
    """What track_frames did to each frame."""

    poses: list[np.ndarray]  # per frame: the pose it was fused at, or for a lost frame the last good one
    lost: list[int]  # indices of the frames tracking lost (not fused)
    log: list[dict]  # per tracked frame (all but the first), as report.json's tracking.frames
    seconds: list[float]  # per tracked frame, the tracker's time (its attempts and the next colour reference)

    @property
    def relocalised(self) -> int:
        """Frames kept only by the wider re-localisation search."""
        return sum(1 for e in self.log if e["relocalised"] and not e["lost"])


def track_frames(volume: TernaryVolume, frames: Iterable[RGBDFrame], *, icp: str = "projective",
                 photometric_weight: float = PHOTO_WEIGHT) -> TrackedFrames:
    """Frame-to-model tracking of frames in memory into `volume`, by the integrator fuse_recording's pose "icp"
    runs (so that benchmarks and tests measure what `kinfu fuse` does): the first frame is fused at its
    T_world_camera (the identity when None); each next one is tracked from the constant-velocity prediction of
    the last two good poses, then from the last good pose, its speed checked over the time since that pose, and
    fused (and made the colour reference) unless lost. Depth as it is to be fused (filter it first). The given
    poses of later frames are only compared (log's given_minus_tracked_m), never used."""
    if not isinstance(volume, TernaryVolume):
        raise ConfigError(f"expected a TernaryVolume, got {type(volume).__name__}", parameter="volume")
    check_number(photometric_weight, "photometric_weight", 0.0, MAX_PHOTO_WEIGHT)
    plan = _PosePlan(mode="icp", source="none", description="frames in memory", world="")
    timing: dict[str, float] = {}
    integrator = _Integrator(volume, plan, None, None, "", "frames", timing, icp=icp,
                             photometric_weight=photometric_weight)
    poses, seconds = [], []
    for i, frame in enumerate(frames):
        if not isinstance(frame, RGBDFrame):
            raise ConfigError(f"item {i}: expected an RGBDFrame, got {type(frame).__name__}", parameter="frames")
        tracked, before = len(integrator.track_log), timing.get("track", 0.0)
        integrator.add(frame, frame.depth)
        if len(integrator.track_log) > tracked:
            seconds.append(timing["track"] - before)
        poses.append(integrator.prev_T.copy())
    return TrackedFrames(poses, list(integrator.lost), integrator.track_log, seconds)


def _hint_falls_back(res: TrackResult) -> bool:
    """Hint mode keeps the robot's pose when ICP from it fails (a view of new territory, too little overlap, a flat
    view): the frame is fused at its TF pose as forced mode would. Moving it by the last refinement instead (the
    tracker's second candidate) strays further than the TF itself once the camera turns: 4.6 against 2.5 cm RMS on
    a synthetic room walk with a 2 cm hand-eye error. Re-localisation's wide search then only tests the TF: a pose
    far from it that passes every check means the TF is wrong (check 5: lost, not fused); one near it is no better
    evidence than the TF (on that walk with an exact TF such poses lay up to 8.9 cm off: 2.4 cm RMS, against 0.27 cm
    with the TF kept)."""
    return (res.lost and not res.tf_disagrees) or (not res.lost and res.relocalised)


def _track_entry(frame: RGBDFrame, res: TrackResult, T_given: np.ndarray | None,
                 fallback: np.ndarray | None = None) -> dict:
    """One frame's tracking in the report: fitness, rmse, agreement, the condition number of its point-to-plane
    system (how well the view pins the pose down; the tracker refuses MAX_CONDITION and above), lost and why, whether
    ICP had the colour term (photometric: colour and a reference frame), the pose
    (None when lost) and, with given poses, the distance between given and tracked camera positions. fallback: the
    pose fused instead when ICP failed in hint mode (tf_fallback; reason says why ICP failed)."""
    T = res.T_world_camera if fallback is None else np.asarray(fallback, dtype=np.float64)
    lost = res.lost and fallback is None
    reason = res.reason if res.lost else "re-localised near the TF pose (not trusted over it)" if fallback is not None \
        else ""
    e = {"index": frame.index, "stamp_ns": frame.stamp_ns, "fitness": round(res.fitness, 4),
         "rmse": None if not np.isfinite(res.rmse) else round(res.rmse, 5),
         "agreement": None if not np.isfinite(res.agreement) else round(res.agreement, 4),
         "condition": None if not np.isfinite(res.condition) else float(f"{res.condition:.3g}"), "lost": lost,
         "tf_fallback": fallback is not None, "reason": reason, "check": res.check, "relocalised": res.relocalised,
         "attempts": res.attempts, "photometric": res.photometric,
         "T_world_camera": None if lost else np.round(T, 6).tolist()}
    if T_given is not None and not lost:
        e["given_minus_tracked_m"] = round(float(np.linalg.norm(np.asarray(T_given)[:3, 3] - T[:3, 3])), 5)
    return e


def _read_out(vol: TernaryVolume) -> tuple[TernaryGrid, dict[str, int], dict[str, dict | None],
                                            o3d.geometry.TriangleMesh, o3d.geometry.PointCloud]:
    """Ternary labels, their counts and bounding boxes (occupied, observed), mesh and surface cloud."""
    grid = vol.ternary_grid()
    bounding_box = {"occupied": _box_of(grid.labels == 1, vol), "observed": _box_of(grid.labels != 0, vol)}
    mesh = vol.extract_mesh()
    return grid, grid.counts(), bounding_box, mesh, mesh_cloud(mesh)


def _box_of(mask: np.ndarray, vol: TernaryVolume) -> dict | None:
    """World and voxel bounds of the True voxels of mask; None when there is none."""
    axes = [np.flatnonzero(mask.any(axis=tuple(a for a in range(3) if a != i))) for i in range(3)]
    if any(len(a) == 0 for a in axes):
        return None
    lo = np.array([a[0] for a in axes])
    hi = np.array([a[-1] + 1 for a in axes])
    return {"min": (vol.origin + lo * vol.voxel_size).round(4).tolist(),
            "max": (vol.origin + hi * vol.voxel_size).round(4).tolist(),
            "voxels_min": lo.tolist(), "voxels_max": hi.tolist()}


def _add(timing: dict[str, float], step: str, seconds: float) -> None:
    timing[step] = timing.get(step, 0.0) + seconds


def _timed(items: Iterable, timing: dict[str, float], step: str) -> Iterator:
    """The items of an iterator, adding the time spent producing them to timing[step]."""
    it = iter(items)
    while True:
        t0 = time.perf_counter()
        try:
            x = next(it)
        except StopIteration:
            _add(timing, step, time.perf_counter() - t0)
            return
        _add(timing, step, time.perf_counter() - t0)
        yield x
