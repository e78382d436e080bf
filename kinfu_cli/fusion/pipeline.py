"""Fuse a recording into a TernaryVolume and write mesh, cloud, volume, ternary labels and a JSON report.

`fuse_recording(path, outdir, FuseOptions(...))` is what `kinfu fuse` calls. Nothing is written until
every frame has been fused; each output file is written atomically, report.json last.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kinfu_cli.core.errors import ConfigError, KinfuError, RecordingError, VolumeError
from kinfu_cli.fusion import filters
from kinfu_cli.fusion.placement import default_origin
from kinfu_cli.fusion.tracking import POSE_MODES, FrameToModelTracker
from kinfu_cli.fusion.volume import TernaryVolume, load_volume
from kinfu_cli.core.progress import progress

OUTPUTS = ("mesh.ply", "cloud.ply", "volume.npz", "ternary.npz", "report.json")
PLACEMENT_FRAMES = 5


@dataclass
class FuseOptions:
    """Options of `kinfu fuse` (see its --help); defaults as KinFu LS."""

    size: float | tuple = 3.0
    resolution: int | tuple | None = None  # default 512 when voxel_size is None too
    voxel_size: float | None = None
    origin: tuple | None = None
    truncation: float = 0.03
    max_weight: int = 128
    min_depth: float = 0.3
    max_depth: float = 4.0
    pose: str | None = None  # None: forced when TF has the camera frame, else icp
    pose_topic: str | None = None
    init: str | None = None
    clear_spheres: list = field(default_factory=list)  # [(x, y, z, r), ...]
    clear_pois: str | None = None
    start: float | None = None
    end: float | None = None
    every: int = 1
    tolerance: float = 0.05
    fill_gaps: int = 2  # fill invalid runs of up to this many pixels between agreeing readings (0: off)
    bilateral: bool = False
    shadow_filter: bool = False
    shadow_baseline: float = 0.08
    plot: bool = False
    color: bool = True
    quiet: bool = False
    roles: dict = field(default_factory=dict)


def _spheres(opts: FuseOptions) -> list[dict]:
    out = []
    for s in opts.clear_spheres:
        s = tuple(float(v) for v in s)
        if len(s) != 4 or not all(np.isfinite(s)) or s[3] <= 0:
            raise ConfigError(f"--clear-sphere {s}: expected x,y,z,r with r > 0")
        out.append({"center": list(s[:3]), "radius": s[3], "source": "--clear-sphere"})
    if opts.clear_pois:
        from kinfu_cli.core.pois import read_pois

        for p in read_pois(opts.clear_pois):
            if not (np.isfinite(p.radius) and p.radius > 0):
                raise ConfigError(f"{opts.clear_pois}: POI {p.id} has radius {p.radius}, expected > 0")
            out.append({"center": [float(v) for v in p.position], "radius": float(p.radius),
                        "source": f"{opts.clear_pois}#{p.id}"})
    return out


def _box_of(mask: np.ndarray, vol: TernaryVolume) -> dict | None:
    axes = [np.flatnonzero(mask.any(axis=tuple(a for a in range(3) if a != i))) for i in range(3)]
    if any(len(a) == 0 for a in axes):
        return None
    lo = np.array([a[0] for a in axes])
    hi = np.array([a[-1] + 1 for a in axes])
    return {"min": (vol.origin + lo * vol.voxel_size).round(4).tolist(),
            "max": (vol.origin + hi * vol.voxel_size).round(4).tolist(),
            "voxels_min": lo.tolist(), "voxels_max": hi.tolist()}


class _Timer:
    def __init__(self):
        self.t: dict[str, float] = {}

    def add(self, key: str, dt: float) -> None:
        self.t[key] = self.t.get(key, 0.0) + dt


def _timed_iter(it, timer: _Timer, key: str):
    it = iter(it)
    while True:
        t0 = time.perf_counter()
        try:
            x = next(it)
        except StopIteration:
            timer.add(key, time.perf_counter() - t0)
            return
        timer.add(key, time.perf_counter() - t0)
        yield x


def fuse_recording(recording: str | Path, outdir: str | Path, opts: FuseOptions | None = None) -> dict:
    """Fuse the depth frames of `recording` and write OUTPUTS (+ PNG slices with opts.plot) into outdir.

    Returns the report (also written as report.json).
    """
    from kinfu_cli.core.pois import poi_frame_warnings
    from kinfu_cli.io.frames import FrameStats, iter_frames
    from kinfu_cli.io.recording import open_recording
    from kinfu_cli.io.roles import detect_roles
    from kinfu_cli.io.tf_buffer import TfBuffer

    opts = opts or FuseOptions()
    t_start = time.perf_counter()
    timer = _Timer()
    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise ConfigError(f"-o {outdir}: exists and is not a folder")
    if opts.pose is not None and opts.pose not in POSE_MODES:
        raise ConfigError(f"--pose {opts.pose!r}: expected one of {', '.join(POSE_MODES)}")
    if opts.pose == "topic" and not opts.pose_topic:
        raise ConfigError("--pose topic needs --pose-topic (a PoseStamped/Odometry topic)")
    if opts.every < 1:
        raise ConfigError(f"--every {opts.every}: expected an integer >= 1")
    spheres = _spheres(opts)

    vol = None
    placement = None
    if opts.init:
        t0 = time.perf_counter()
        vol = load_volume(opts.init)
        timer.add("load_init", time.perf_counter() - t0)
        placement = f"--init {opts.init}"
        for s in spheres:
            vol.clear_sphere(s["center"], s["radius"])
    else:
        # validate the grid options now (and refuse impossible sizes) before reading anything
        _new_volume(opts, origin=(0.0, 0.0, 0.0))

    with open_recording(recording) as rec:
        tf = TfBuffer.from_recording(rec)
        roles = detect_roles(rec, tf=tf, **{k: v for k, v in opts.roles.items() if v is not None})
        has_tf = False
        if roles.world_frame and roles.camera_frame:
            try:
                tf._split_path(roles.world_frame, roles.camera_frame)
                has_tf = True
            except KinfuError:
                has_tf = False
        mode = opts.pose or ("forced" if has_tf else "icp")
        if mode in ("forced", "hint") and not has_tf:
            raise RecordingError(f"{rec.path}: --pose {mode} needs TF from {roles.world_frame or 'a world frame'} "
                                 f"to camera frame {roles.camera_frame or '?'} (use --pose icp or --pose topic, or "
                                 f"set --camera-frame / --world-frame)")
        if mode == "topic":
            source = "topic"
            source_desc = f"topic {opts.pose_topic}"
        elif mode == "icp" and not has_tf:
            source = "none"
            source_desc = "none (first camera pose = world origin)"
        else:
            source = "tf"
            source_desc = f"tf {roles.world_frame} <- {roles.camera_frame}"
            if mode == "icp":
                source_desc += " (first frame only)"
        world = _world_frame(rec, source, roles, opts.pose_topic)
        if vol is not None and vol.frame and world and vol.frame != world:
            raise RecordingError(f"--init {opts.init}: the volume was fused in frame {vol.frame!r}, but {rec.path} "
                                 f"gives camera poses in {world!r}")
        warnings = poi_frame_warnings(opts.clear_pois, world or (vol.frame if vol is not None else ""),
                                      "--clear-pois")
        stats = FrameStats()
        frames = iter_frames(rec, roles, pose_source=source, pose_topic=opts.pose_topic, start_s=opts.start,
                             end_s=opts.end, every=opts.every, stats=stats, tf=tf,
                             tolerance_s=opts.tolerance)
        frames = _timed_iter(frames, timer, "read")
        tracker = FrameToModelTracker() if mode in ("icp", "hint") else None
        track_log: list[dict] = []
        buffered: list = []
        used = 0
        filter_drops: dict[str, int] = {}
        gap_pixels = 0
        prev_T = None
        min_d = opts.min_depth
        max_d = opts.max_depth

        def prepare(frame):
            nonlocal gap_pixels
            t0 = time.perf_counter()
            d = filters.range_filter(frame.depth, min_d, max_d)
            if opts.fill_gaps:
                d, n = filters.fill_gaps(d, opts.fill_gaps)
                gap_pixels += n
            if opts.bilateral:
                d = filters.bilateral(d)
            if opts.shadow_filter:
                d = filters.shadow_veil_filter(d, frame.K, baseline=opts.shadow_baseline)
            timer.add("filter", time.perf_counter() - t0)
            if not np.any(d > 0):
                reason = f"no valid depth in [{min_d}, {max_d}] m after filtering"
                filter_drops[reason] = filter_drops.get(reason, 0) + 1
                return None
            return d

        def fuse_one(frame, d):
            nonlocal used, prev_T
            T_given = frame.T_world_camera
            if T_given is not None and not np.all(np.isfinite(T_given)):
                raise VolumeError(f"{rec.path}: frame {frame.index} (stamp {frame.stamp_ns} ns): camera pose is "
                                  f"not finite (NaN or inf)")
            if mode in ("forced", "topic"):
                T = T_given
            elif prev_T is None and (mode == "icp" or vol.frames_integrated == 0):
                # the first frame anchors the model: its given pose (identity when icp has none)
                T = T_given if T_given is not None or mode == "hint" else np.eye(4)
            else:  # icp tracks from the previous pose, hint from the given one
                t0 = time.perf_counter()
                res = tracker.track(vol, d, frame.K, prev_T if mode == "icp" else T_given)
                timer.add("track", time.perf_counter() - t0)
                T = res.T_world_camera
                track_log.append(_track_entry(frame, res, T_given))
            t0 = time.perf_counter()
            try:
                vol.integrate(d, frame.K, T, frame.color)
            except VolumeError as exc:
                raise VolumeError(f"{rec.path}: frame {frame.index} (stamp {frame.stamp_ns} ns): {exc}") from None
            timer.add("integrate", time.perf_counter() - t0)
            prev_T = np.asarray(T, dtype=np.float64)
            used += 1

        n_place = 1 if mode == "icp" else PLACEMENT_FRAMES
        for frame in progress(frames, desc="fusing", quiet=opts.quiet, unit="frame"):
            d = prepare(frame)
            if d is None:
                continue
            if vol is None:
                buffered.append((frame, d))
                if len(buffered) < n_place:
                    continue
                vol, placement = _place(opts, buffered, mode)
                for f, dd in buffered:
                    fuse_one(f, dd)
                buffered = []
                continue
            fuse_one(frame, d)
        if vol is None and buffered:
            vol, placement = _place(opts, buffered, mode)
            for f, dd in buffered:
                fuse_one(f, dd)
        if used == 0:
            dropped = {**stats.dropped, **filter_drops}
            why = "; ".join(f"{k}: {v}" for k, v in dropped.items()) or "no depth frames in the selection"
            raise RecordingError(f"{rec.path}: no usable depth frames ({why})")
        recording_path = str(rec.path)
        roles_dict = roles.as_dict()
        vol.frame = vol.frame or world

    if not opts.init:
        for s in spheres:
            vol.clear_sphere(s["center"], s["radius"])

    # ---------------------------------------------------------------- read-out and outputs
    import open3d as o3d

    from kinfu_cli.core.grid import save_ternary
    from kinfu_cli.core.atomic import atomic_path, write_json

    t0 = time.perf_counter()
    grid = vol.ternary_grid()
    counts = grid.counts()
    occ_box = _box_of(grid.labels == 1, vol)
    obs_box = _box_of(grid.labels != 0, vol)
    mesh = vol.extract_mesh()
    cloud = o3d.geometry.PointCloud()
    cloud.points, cloud.colors, cloud.normals = mesh.vertices, mesh.vertex_colors, mesh.vertex_normals
    timer.add("extract", time.perf_counter() - t0)

    t0 = time.perf_counter()
    outdir.mkdir(parents=True, exist_ok=True)
    with atomic_path(outdir / "mesh.ply") as tmp:
        if not o3d.io.write_triangle_mesh(str(tmp), mesh):
            raise OSError(f"could not write {outdir / 'mesh.ply'}")
    with atomic_path(outdir / "cloud.ply") as tmp:
        if not o3d.io.write_point_cloud(str(tmp), cloud):
            raise OSError(f"could not write {outdir / 'cloud.ply'}")
    vol.save(outdir / "volume.npz")
    save_ternary(outdir / "ternary.npz", grid)
    plots = []
    if opts.plot:
        from kinfu_cli.report.volume_plot import plot_slices

        plots = [str(p.name) for p in plot_slices(grid, outdir)]
    timer.add("write", time.perf_counter() - t0)
    timer.add("total", time.perf_counter() - t_start)

    dropped = dict(stats.dropped)
    for k, v in filter_drops.items():
        dropped[k] = dropped.get(k, 0) + v
    report = {
        "recording": recording_path,
        "roles": roles_dict,
        "pose_mode": mode,
        "pose_source": source_desc,
        "world_frame": vol.frame,
        "frames": {"depth_messages": stats.depth_messages, "used": used, "skipped_every": stats.skipped,
                   "without_color": stats.without_color, "dropped": dropped,
                   "dropped_total": int(sum(dropped.values())), "every": opts.every, "start_s": opts.start,
                   "end_s": opts.end},
        "tracking": None if tracker is None else {
            "frames": track_log, "lost_frames": [t["index"] for t in track_log if t["lost"]],
            "lost": int(sum(t["lost"] for t in track_log)),
            "mean_fitness": float(np.mean([t["fitness"] for t in track_log])) if track_log else None},
        "grid": {"origin": vol.origin.tolist(), "voxel_size": vol.voxel_size, "shape": list(vol.shape),
                 "size_m": (np.array(vol.shape) * vol.voxel_size).tolist(), "truncation": vol.truncation,
                 "max_weight": vol.max_weight, "min_depth": min_d, "max_depth": max_d, "placement": placement,
                 "blocks_stored": vol.n_blocks_allocated, "memory_MB": round(vol.memory_bytes() / 2**20, 1),
                 "frames_in_volume": vol.frames_integrated},
        "filters": {"range": [min_d, max_d], "fill_gaps": opts.fill_gaps, "gap_pixels_filled": gap_pixels,
                    "bilateral": opts.bilateral, "shadow_veil": opts.shadow_filter},
        "cleared_spheres": spheres,
        "counts": counts,
        "bounding_box": {"occupied": occ_box, "observed": obs_box},
        "mesh": {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles)},
        "cloud": {"points": len(cloud.points)},
        "timing_s": {k: round(v, 3) for k, v in timer.t.items()},
        "outputs": list(OUTPUTS) + plots,
        "warnings": warnings,
    }
    write_json(outdir / "report.json", report)
    return report


def _world_frame(rec, source: str, roles, pose_topic: str | None) -> str:
    """Name of the frame the camera poses of this run are in ("" when not known: ICP from an unnamed first pose,
    or a pose topic without frame_id)."""
    if source == "tf":
        return roles.world_frame or ""
    if source == "topic":
        from kinfu_cli.io.messages import header_frame

        rec.require_topic(pose_topic, "pose topic")
        msg = rec.first_message(pose_topic)
        return header_frame(msg).lstrip("/") if msg is not None else ""
    return ""


def _track_entry(frame, res, T_given) -> dict:
    e = {"index": frame.index, "stamp_ns": frame.stamp_ns, "fitness": round(res.fitness, 4),
         "rmse": None if not np.isfinite(res.rmse) else round(res.rmse, 5), "lost": res.lost, "reason": res.reason,
         "T_world_camera": np.round(res.T_world_camera, 6).tolist()}
    if T_given is not None:
        e["given_minus_tracked_m"] = round(float(np.linalg.norm(np.asarray(T_given)[:3, 3]
                                                                - res.T_world_camera[:3, 3])), 5)
    return e


def _new_volume(opts: FuseOptions, origin) -> TernaryVolume:
    res = opts.resolution if (opts.resolution is not None or opts.voxel_size is not None) else 512
    return TernaryVolume(size=opts.size, resolution=res if opts.voxel_size is None else 512,
                         voxel_size=opts.voxel_size, origin=origin, truncation=opts.truncation,
                         max_weight=opts.max_weight, min_depth=opts.min_depth, max_depth=opts.max_depth,
                         color=opts.color)


def _place(opts: FuseOptions, buffered, mode: str):
    """Create the volume: at --origin, else centred on the back-projected depth of the first frames."""
    if opts.origin is not None:
        return _new_volume(opts, opts.origin), "--origin"
    views = []
    for f, d in buffered:
        T = f.T_world_camera
        if mode == "icp" and T is None:
            T = np.eye(4)
        if T is None or not np.all(np.isfinite(T)):
            continue
        views.append((d, f.K, T))
    probe = _new_volume(opts, (0.0, 0.0, 0.0))
    size = np.array(probe.shape) * probe.voxel_size
    origin = default_origin(views, size)
    return _new_volume(opts, origin), f"centred on the first {len(views)} frame(s)"
