"""The whole synthetic recording: initial scan, a person changes the table, views after the change.

`make_scenario(seed, kind, ...)` builds everything in memory (scenes before/after, camera path and robot joint
angles, hand trajectory, ground truth); frames are rendered on demand (`scenario.render(i)`, deterministic per frame).
`write_recordings(scenario, [paths])` streams it into MCAP / ROS 1 bag / ROS 2 bag folders at once through
`kinfu_cli.io.writers.RecordingWriter`; `write_ground_truth(scenario, folder)` writes the ground-truth files.

Timeline (seconds after `t0_ns`): camera info, /tf_static at 0; scan frames at `frame_rate_hz` from 0.5 s; the hand
trajectory starts 1 s after the last scan frame; the after-change views start 2 s after the hand left. /tf carries the
arm's joint chain at 10 Hz and at every frame stamp (joint angles interpolated linearly between frames), so the camera
pose at a frame stamp is exact.

Topics: /camera/depth/image_raw (16UC1 mm) or /camera/depth/image_raw/compressedDepth (PNG, image_transport layout),
/camera/color/image_raw (rgb8) or /camera/color/image_raw/compressed (jpeg/png), /camera/depth/camera_info, /tf,
/tf_static, /hand/pose (geometry_msgs/PoseStamped in `world`). Depth and colour share the `camera_optical` frame.
Optionally (`camera_pose_topic`) a geometry_msgs/PoseStamped topic with the pose of `camera_optical` in `world` at
every depth frame stamp (the pose the TF chain gives there), for fusing with poses from a topic.
"""

from __future__ import annotations

import dataclasses
import json
import os
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d

from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, RecordingError
from kinfu_cli.core.poses import look_at
from kinfu_cli.core.progress import progress
from kinfu_cli.io.polhemus import read_polhemus
from kinfu_cli.io.trajectory import Trajectory
from kinfu_cli.io.writers import RecordingWriter
from kinfu_cli.io.messages import c_stderr_silenced
from kinfu_cli.io.mesh_faces import faces_outside_vertices
from kinfu_cli.sim.household import household_scene
from kinfu_cli.sim.hand import Action, HandChange, synth_hand_trajectory, write_polhemus
from kinfu_cli.sim.robot import CAMERA_FRAME, LINKS, WORLD_FRAME, RobotArm
from kinfu_cli.io.labelled_cloud import write_labelled_cloud
from kinfu_cli.sim.scene import (FLOOR_COLOUR, LABEL_FLOOR, LABEL_TABLE, PALETTE, TABLE_COLOUR, Scene,
                                 make_tabletop_scene, movable_objects, random_object, scene_label_cloud, segmentation_scene)
from kinfu_cli.sim.sensor import DepthSensor, SensorFrame, kinect_v1_intrinsics

KINDS = ("place", "remove", "pick-and-place")
LAYOUTS = ("tabletop", "objects", "household")  # make_tabletop_scene, segmentation_scene, household_scene
# (n_objects applies to the tabletop only)
LABELS_SPACING = 0.004  # ground_truth/labels.ply: one labelled point per 4 mm x 4 mm of object and table surface
LABELS_VOXEL = 0.01  # ground_truth/labels.npz: per-voxel labels on a 1 cm grid (sim.voxel_labels; 5 mm costs 8x)
T0_NS = 1_767_225_600_000_000_000  # 2026-01-01T00:00:00Z: fixed, so recordings are reproducible

DEPTH_TOPIC = "/camera/depth/image_raw"
COLOR_TOPIC = "/camera/color/image_raw"
INFO_TOPIC = "/camera/depth/camera_info"
HAND_TOPIC = "/hand/pose"
TF_RATE_HZ = 10.0

#: rates a generated recording may have: inf made an infinite number of samples (a traceback), and a hand tracker
#: faster than 10 kHz or a camera faster than 1 kHz is no recording anyone replays; slower than one frame in 100 s
#: is none either (1e-300 Hz put the frames past any time stamp: an overflow)
MAX_HAND_RATE_HZ = 1e4
MAX_FRAME_RATE_HZ = 1e3
MIN_FRAME_RATE_HZ = 0.01
MIN_HAND_RATE_HZ = 1.0  # a hand tracker slower than this gives a motion of a few seconds a sample or two


@dataclass
class CameraFrame:
    """One depth+colour frame: index, stamp (ns), true camera-to-world pose, joint angles, phase (scan|after)."""

    index: int
    stamp_ns: int
    T_world_camera: np.ndarray
    q: np.ndarray
    phase: str


@dataclass
class Scenario:
    """A synthetic recording, in memory. `hand` has t in seconds after `t0_ns`; `changes` are the true scene
    changes (object centres); `hand_changes` the wrist pauses that produced them."""

    seed: int
    kind: str
    width: int
    height: int
    K: np.ndarray
    sensor: DepthSensor
    robot: RobotArm
    scene_before: Scene
    scene_after: Scene
    frames: list[CameraFrame]
    hand: Trajectory
    hand_changes: list[HandChange]
    changes: list[dict]
    t0_ns: int = T0_NS
    hand_rate_hz: float = 100.0
    meta: dict = field(default_factory=dict)

    @property
    def end_ns(self) -> int:
        return max(self.frames[-1].stamp_ns, self.t0_ns + int(round(self.hand.t[-1] * 1e9)))

    def scene_for(self, frame: CameraFrame) -> Scene:
        return self.scene_before if frame.phase == "scan" else self.scene_after

    def render(self, i: int) -> SensorFrame:
        """Frame i as the sensor sees it (noise seeded by the frame index, so any order gives the same images)."""
        f = self.frames[i]
        return self.sensor.render_frame(self.scene_for(f), f.T_world_camera, frame_seed=i)

    def joint_angles_at(self, stamp_ns: np.ndarray) -> np.ndarray:
        """Joint angles (N, 6) at the stamps, linear between frames, held before the first / after the last."""
        ts = np.array([f.stamp_ns for f in self.frames], dtype=np.float64)
        Q = np.array([f.q for f in self.frames])
        s = np.asarray(stamp_ns, dtype=np.float64)
        return np.stack([np.interp(s, ts, Q[:, j]) for j in range(Q.shape[1])], axis=1)


def make_scenario(seed: int = 0, kind: str = "pick-and-place", width: int = 320, height: int = 240, frames: int = 36,
                  n_objects: int = 4, noise: bool = True, hand_rate_hz: float = 100.0, frame_rate_hz: float = 5.0,
                  after_fraction: float = 1 / 3, layout: str = "tabletop") -> Scenario:
    """Build a seeded scenario. kind: place | remove | pick-and-place. frames: total depth frames, `after_fraction`
    of them after the change (at least 1 on each side). layout: "tabletop" (`make_tabletop_scene` with n_objects)
    or "objects" (`segmentation_scene`; only objects standing alone are removed or moved) or "household"
    (`household.household_scene`, YCB-like objects, likewise)."""
    if layout not in LAYOUTS:
        raise ConfigError(f"expected one of {', '.join(LAYOUTS)}, got {layout!r}", parameter="layout")
    if kind not in KINDS:
        raise ConfigError(f"expected one of {', '.join(KINDS)}, got {kind!r}", parameter="kind")
    if frames < 2:
        raise ConfigError(f"expected at least 2 (scan and after the change), got {frames}", parameter="frames")
    if width < 8 or height < 6 or width > 4096 or height > 4096:
        raise ConfigError(f"expected 8x6 to 4096x4096 pixels, got {width}x{height}", parameter="width/height")
    check_number(hand_rate_hz, "hand_rate_hz", MIN_HAND_RATE_HZ, MAX_HAND_RATE_HZ, unit="Hz")
    check_number(frame_rate_hz, "frame_rate_hz", MIN_FRAME_RATE_HZ, MAX_FRAME_RATE_HZ, unit="Hz")
    if kind in ("remove", "pick-and-place") and n_objects < 1:
        raise ConfigError(f"the {kind} scenario needs at least one object, got {n_objects}", parameter="n_objects")
    rng = np.random.default_rng([seed, 7])
    scene = (make_tabletop_scene(seed, n_objects) if layout == "tabletop" else
             household_scene(seed) if layout == "household" else segmentation_scene(seed))
    table = scene.table
    region = ((-0.42, 0.42), (-0.25, 0.25))  # where changes happen: well inside the table, seen by the arm

    # ---- the change -----------------------------------------------------------------------------------
    if kind == "place":
        used = {o.shape for o in scene.objects}
        shape = next((s for s in ("cone", "torus", "cylinder", "box", "sphere") if s not in used), "box")
        used_c = [tuple(o.colour) for o in scene.objects]
        colour = next((c for c in PALETTE if tuple(float(x) for x in c) not in used_c), PALETTE[0])
        new = random_object(rng, f"obj{len(scene.objects) + 1}", shape, colour, table)
        xy = scene.free_spot(rng, new.footprint_radius, region=region)
        after = scene.with_change("placement", new, xy)
        moved = [("placement", after.object(new.id))]
    else:
        pool = list(scene.objects) if layout == "tabletop" else movable_objects(scene)
        candidates = [o for o in pool if region[0][0] <= o.center[0] <= region[0][1]] or pool
        obj = candidates[int(rng.integers(len(candidates)))]
        if kind == "remove":
            after = scene.with_change("removal", obj.id)
            moved = [("removal", obj)]
        else:
            others = scene.with_change("removal", obj.id)
            xy = others.free_spot(rng, obj.footprint_radius, region=region, avoid=obj.center[:2], min_dist=0.3)
            after = scene.with_change("move", obj.id, position=xy)
            moved = [("pick", obj), ("place", after.object(obj.id))]
    hand_points = [_grasp_point(o) for _, o in moved]

    # ---- camera path and arm --------------------------------------------------------------------------
    robot = RobotArm()
    n_after = max(1, int(round(frames * after_fraction)))
    n_scan = frames - n_after
    if n_scan < 1:
        n_scan, n_after = 1, frames - 1
    centre = np.array([table.center[0], table.center[1], table.top_z])
    scan = [_reachable(robot, lambda r, k=k: _arc_pose(centre, k, n_scan, r, rng_for(seed, k), (20.0, 160.0),
                                                         (42.0, 58.0)), 0.85) for k in range(n_scan)]
    target = np.mean([o.center for _, o in moved], axis=0)
    after_poses = [_reachable(robot, lambda r, k=k: _arc_pose(target, k, n_after, r, rng_for(seed, 1000 + k),
                                                               (45.0, 135.0), (52.0, 64.0)), 0.7)
                   for k in range(n_after)]
    Q = robot.ik_path(scan + after_poses)

    # ---- timeline ----------------------------------------------------------------------------------------
    dt = 1.0 / frame_rate_hz
    t_scan = 0.5 + dt * np.arange(n_scan)
    hand_t0 = float(t_scan[-1] + 1.0)
    traj, hand_changes = synth_hand_trajectory([Action(k, tuple(p)) for (k, _), p in zip(moved, hand_points)],
                                               seed=seed, rate_hz=hand_rate_hz, table=table, t0=hand_t0)
    t_after = traj.t[-1] + 2.0 + dt * np.arange(n_after)
    stamps = np.concatenate([t_scan, t_after])
    cam_frames = [CameraFrame(i, T0_NS + int(round(stamps[i] * 1e9)), T, Q[i], "scan" if i < n_scan else "after")
                  for i, T in enumerate(scan + after_poses)]
    # exact camera poses from the chain (the same numbers the TF tree yields)
    for f in cam_frames:
        f.T_world_camera = robot.fk(f.q)
    traj = dataclasses.replace(traj, t0_ns=T0_NS, frame=WORLD_FRAME, source="kinfu synth hand")

    changes = []
    for (k, o), hc in zip(moved, hand_changes):
        changes.append({"position": [float(c) for c in o.center], "kind": k, "time": float(hc.time),
                        "stamp_ns": T0_NS + int(round(hc.time * 1e9)), "object": o.id,
                        "hand_position": [float(c) for c in hc.position]})
    K = kinect_v1_intrinsics(width, height)
    sensor = DepthSensor(K, width, height, noise=noise, seed=seed)
    return Scenario(seed, kind, width, height, K, sensor, robot, scene, after, cam_frames, traj, hand_changes,
                    changes, T0_NS, hand_rate_hz,
                    meta={"n_scan": n_scan, "n_after": n_after, "frame_rate_hz": frame_rate_hz, "noise": noise,
                          "n_objects": n_objects, **({"layout": layout} if layout != "tabletop" else {})})


def rng_for(seed: int, k: int) -> np.random.Generator:
    return np.random.default_rng([seed, 11, k])


def _grasp_point(o) -> np.ndarray:
    """Where the wrist is while grasping/releasing the object: above it, a little towards the person (-y)."""
    h = o.size[2]
    return np.array([o.center[0], o.center[1] - (0.5 * o.footprint_radius + 0.03), o.center[2] + 0.5 * h + 0.05])


def _arc_pose(target: np.ndarray, k: int, n: int, radius: float, rng: np.random.Generator,
              az_range: tuple[float, float], el_range: tuple[float, float]) -> np.ndarray:
    s = k / max(n - 1, 1)
    az = np.deg2rad(az_range[0] + (az_range[1] - az_range[0]) * s)
    el = np.deg2rad(el_range[0] + (el_range[1] - el_range[0]) * (0.5 - 0.5 * np.cos(2 * np.pi * s)))
    eye = target + radius * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    look = target + rng.normal(0.0, 0.02, 3) * np.array([1.0, 1.0, 0.5])
    return look_at(eye, look)


def _reachable(robot: RobotArm, pose_at_radius, radius: float) -> np.ndarray:
    """The pose at `radius`, or closer in steps of 5 cm until the arm reaches it."""
    r = radius
    while True:
        T = pose_at_radius(r)
        try:
            robot.ik(T)
            return T
        except ConfigError:
            r -= 0.05
            if r < 0.4:
                raise


# ---- writing -----------------------------------------------------------------------------------------------

def write_recordings(scenario: Scenario, paths: list[str | os.PathLike], depth_format: str = "png",
                     color_format: str = "jpeg", quiet: bool = True, compression: str | None = None,
                     jpeg_quality: int = 75, camera_pose_topic: str | None = None) -> list[Path]:
    """Write the scenario into every path at once (container from the suffix: .mcap, .bag, else a ROS 2 folder).

    depth_format: "png" (sensor_msgs/CompressedImage compressedDepth on .../compressedDepth) or "raw" (16UC1 Image).
    color_format: "jpeg" or "png" (CompressedImage on .../compressed) or "raw" (rgb8 Image). Frames are rendered once.
    compression: None or "zstd" (MCAP chunks, ROS 2 messages; bz2 chunks for .bag).
    camera_pose_topic: also write geometry_msgs/PoseStamped (frame `world`) on this topic at every depth frame
    stamp: the true pose of the camera optical frame in `world` (T_world_camera, as the TF chain gives it).
    """
    if depth_format not in ("png", "raw"):
        raise ConfigError(f"expected png or raw, got {depth_format!r}", parameter="depth_format")
    if not 1 <= int(jpeg_quality) <= 100:
        raise ConfigError(f"expected 1..100, got {jpeg_quality}", parameter="jpeg_quality")
    if color_format not in ("jpeg", "png", "raw"):
        raise ConfigError(f"expected jpeg, png or raw, got {color_format!r}", parameter="color_format")
    check_camera_pose_topic(camera_pose_topic, depth_format, color_format)
    sc = scenario
    events = _events(sc)
    with ExitStack() as stack:
        writers = [stack.enter_context(RecordingWriter(p, compression=_compression_for(p, compression)))
                   for p in paths]
        for ev in progress(events, total=len(events), desc="synth", quiet=quiet, unit="msg"):
            stamp, what, arg = ev
            if what == "static":
                for w in writers:
                    w.write_tf(stamp, sc.robot.static_transforms(), static=True)
            elif what == "tf":
                tfs = sc.robot.joint_transforms(arg)
                for w in writers:
                    w.write_tf(stamp, tfs)
            elif what == "hand":
                T = np.eye(4)
                if sc.hand.rotations is not None:
                    T[:3, :3] = sc.hand.rotations[arg]
                T[:3, 3] = sc.hand.positions[arg]
                for w in writers:
                    w.write_pose(HAND_TOPIC, stamp, WORLD_FRAME, T)
            elif what == "frame":
                fr = sc.render(arg)
                depth_mm = depth_to_mm(fr.depth)
                for w in writers:
                    if camera_pose_topic:
                        w.write_pose(camera_pose_topic, stamp, WORLD_FRAME, sc.frames[arg].T_world_camera)
                    w.write_camera_info(INFO_TOPIC, stamp, CAMERA_FRAME, sc.K, sc.width, sc.height)
                    if depth_format == "png":
                        w.write_compressed_depth(DEPTH_TOPIC + "/compressedDepth", stamp, CAMERA_FRAME, depth_mm)
                    else:
                        w.write_image(DEPTH_TOPIC, stamp, CAMERA_FRAME, depth_mm, "16UC1")
                    if color_format == "raw":
                        w.write_image(COLOR_TOPIC, stamp, CAMERA_FRAME, fr.color, "rgb8")
                    else:
                        w.write_compressed_image(COLOR_TOPIC + "/compressed", stamp, CAMERA_FRAME, fr.color,
                                                 fmt=color_format, quality=jpeg_quality)
    return [Path(p) for p in paths]


def _compression_for(path, compression: str | None) -> str | None:
    if compression is None:
        return None
    suffix = Path(path).suffix.lower()
    if suffix == ".bag":
        return "bz2" if compression == "zstd" else compression
    return compression


def depth_to_mm(depth_m: np.ndarray) -> np.ndarray:
    """float metres (0 invalid) -> uint16 millimetres (0 invalid), rounded."""
    mm = np.round(np.asarray(depth_m, dtype=np.float64) * 1000.0)
    return np.clip(mm, 0, 65535).astype(np.uint16)


def _events(sc: Scenario) -> list[tuple[int, str, object]]:
    """(stamp_ns, kind, argument) in time order: static TF, dynamic TF, hand poses, frames."""
    order = {"static": 0, "tf": 1, "frame": 2, "hand": 3}
    ev: list[tuple[int, str, object]] = [(sc.t0_ns, "static", None)]
    frame_stamps = np.array([f.stamp_ns for f in sc.frames], dtype=np.int64)
    grid = sc.t0_ns + np.arange(0.0, (sc.end_ns - sc.t0_ns) / 1e9 + 1e-9, 1.0 / TF_RATE_HZ) * 1e9
    tf_stamps = np.unique(np.concatenate([grid.astype(np.int64), frame_stamps]))
    Q = sc.joint_angles_at(tf_stamps)
    for f in sc.frames:  # exact keyframe angles at frame stamps
        Q[np.searchsorted(tf_stamps, f.stamp_ns)] = f.q
    ev += [(int(s), "tf", q) for s, q in zip(tf_stamps, Q)]
    ev += [(f.stamp_ns, "frame", f.index) for f in sc.frames]
    hand_ns = sc.t0_ns + np.round(sc.hand.t * 1e9).astype(np.int64)
    ev += [(int(s), "hand", i) for i, s in enumerate(hand_ns)]
    ev.sort(key=lambda e: (e[0], order[e[1]]))
    return ev


def recording_topics(depth_format: str = "png", color_format: str = "jpeg",
                     camera_pose_topic: str | None = None) -> dict:
    """Topic of each role in a recording written with these formats ("camera_pose" only when one is written)."""
    topics = {"depth": DEPTH_TOPIC + ("/compressedDepth" if depth_format == "png" else ""),
              "color": COLOR_TOPIC + ("" if color_format == "raw" else "/compressed"),
              "camera_info": INFO_TOPIC, "hand": HAND_TOPIC, "tf": "/tf", "tf_static": "/tf_static"}
    if camera_pose_topic:
        topics["camera_pose"] = camera_pose_topic
    return topics


def check_camera_pose_topic(topic: str | None, depth_format: str = "png", color_format: str = "jpeg") -> None:
    """ConfigError about the camera pose topic unless it is None or an absolute topic name of its own."""
    if topic is None:
        return
    taken = set(recording_topics(depth_format, color_format).values())
    if not topic.startswith("/") or len(topic) < 2 or any(c.isspace() for c in topic) or topic.endswith("/"):
        raise ConfigError(f"expected an absolute topic name such as /camera/pose, got {topic!r}",
                          parameter="camera_pose_topic")
    if topic in taken:
        raise ConfigError(f"{topic} is already used by the recording (topics: {', '.join(sorted(taken))})",
                          parameter="camera_pose_topic")


def write_ground_truth(scenario: Scenario, folder: str | os.PathLike, topics: dict | None = None) -> Path:
    """Write ground truth into `folder` (atomically, as a whole): scene_before.ply, scene_after.ply, objects/<id>.ply
    + table.ply + floor.ply (after state), labels.ply (the after state's surface points with object labels,
    `io.labelled_cloud`), changes.json, camera_poses.txt, hand.traj (Polhemus format, 100 Hz)."""
    sc = scenario
    with atomic_dir(folder) as tmp:
        for name, scene in (("scene_before.ply", sc.scene_before), ("scene_after.ply", sc.scene_after)):
            _write_mesh(tmp / name, scene.mesh())
        (tmp / "objects").mkdir()
        for o in sc.scene_after.present_objects:
            m = o.mesh
            m.paint_uniform_color(o.colour)
            _write_mesh(tmp / "objects" / f"{o.id}.ply", m)
        _write_mesh(tmp / "objects" / "table.ply", sc.scene_after.table.mesh().paint_uniform_color(TABLE_COLOUR))
        _write_mesh(tmp / "objects" / "floor.ply", sc.scene_after.floor_mesh().paint_uniform_color(FLOOR_COLOUR))
        pts, labels = scene_label_cloud(sc.scene_after, spacing=LABELS_SPACING, seed=sc.seed)
        write_labelled_cloud(tmp / "labels.ply", pts, labels)
        write_scene_voxel_labels(tmp / "labels.npz", sc.scene_after)
        write_json(tmp / "changes.json", ground_truth_json(sc, topics))
        lines = ["# stamp_s (Unix seconds of the depth message) then the true T_world_camera, 16 numbers row-major"]
        for f in sc.frames:
            lines.append(f"{f.stamp_ns // 1_000_000_000}.{f.stamp_ns % 1_000_000_000:09d} "
                         + " ".join(f"{v:.9f}" for v in f.T_world_camera.reshape(-1)))
        (tmp / "camera_poses.txt").write_text("\n".join(lines) + "\n")
        write_polhemus(tmp / "hand.traj", sc.hand, rate_hz=100.0)
    return Path(folder)


def write_scene_voxel_labels(path: str | os.PathLike, scene: Scene, voxel_size: float = LABELS_VOXEL) -> Path:
    """labels.npz (`sim.voxel_labels`) of the scene's table top and what stands on it: 0 table (and the floor
    where the box reaches it), 1.. the objects' labels (as in labels.ply and changes.json)."""
    from kinfu_cli.sim.voxel_labels import write_voxel_labels

    def distances(p):
        return [(0 if label in (LABEL_FLOOR, LABEL_TABLE) else label, d) for label, d in scene._part_distances(p)]

    t = scene.table
    top = max([t.top_z] + [o.center[2] + o.size[2] / 2 for o in scene.present_objects])
    lo = (t.center[0] - t.size[0] / 2 - 0.05, t.center[1] - t.size[1] / 2 - 0.05, t.top_z - t.thickness - 0.02)
    hi = (t.center[0] + t.size[0] / 2 + 0.05, t.center[1] + t.size[1] / 2 + 0.05, top + 0.05)
    return write_voxel_labels(path, distances, lo, hi, voxel_size)


def ground_truth_json(sc: Scenario, topics: dict | None = None) -> dict:
    before = {o.id: o for o in sc.scene_before.objects}
    after = {o.id: o for o in sc.scene_after.objects}
    objects = []
    for oid in list(before) + [i for i in after if i not in before]:
        b, a = before.get(oid), after.get(oid)
        cur = a if a is not None else b
        present_after = bool(a is not None and a.present)
        d = {"id": oid, "shape": cur.shape,
             "center": [float(c) for c in (cur.center if present_after or b is None else b.center)],
             "size": [float(s) for s in cur.size], "params": dict(cur.params), "yaw": float(cur.yaw),
             "colour": [float(c) for c in cur.colour], "label": sc.scene_after.label_of(oid),
             "present_before": bool(b is not None and b.present), "present_after": present_after}
        if b is not None and a is not None and b.center != a.center:
            d["center_before"] = [float(c) for c in b.center]
        objects.append(d)
    return {
        "changes": sc.changes,
        "objects": objects,
        "table": sc.scene_before.table.to_json(),
        "camera": {"K": sc.K.tolist(), "width": sc.width, "height": sc.height, "frame": CAMERA_FRAME,
                   "model": "kinect_v1 (fx = fy = 585 at 640x480)", "min_range": sc.sensor.min_range,
                   "max_range": sc.sensor.max_range, "noise": sc.meta.get("noise", True)},
        "seed": sc.seed,
        "scenario": sc.kind,
        **({"layout": sc.meta["layout"]} if sc.meta.get("layout") else {}),
        "t0_ns": sc.t0_ns,
        "frames": {"count": len(sc.frames), "scan": sc.meta.get("n_scan"), "after": sc.meta.get("n_after"),
                   "rate_hz": sc.meta.get("frame_rate_hz"), "first_after": sc.meta.get("n_scan")},
        "hand": {"topic": HAND_TOPIC, "frame": WORLD_FRAME, "rate_hz": sc.hand_rate_hz,
                 "start_time": float(sc.hand.t[0]), "end_time": float(sc.hand.t[-1]),
                 "traj_file": "hand.traj (100 Hz, t = start_time + i / 100)"},
        "frames_tree": {"world_frame": WORLD_FRAME, "camera_frame": CAMERA_FRAME,
                        "chain": [WORLD_FRAME, *LINKS, CAMERA_FRAME]},
        "topics": topics or recording_topics(),
        "time_unit": "seconds after t0_ns (the recording starts at t0_ns)",
    }


def _write_mesh(path: Path, mesh: o3d.geometry.TriangleMesh) -> None:
    mesh.compute_vertex_normals()
    if not o3d.io.write_triangle_mesh(str(path), mesh, write_ascii=False, compressed=False,
                                      write_vertex_normals=False, print_progress=False):
        raise ConfigError(f"{path}: could not write the mesh")


# ---- reading ground truth back ---------------------------------------------------------------------------------

@dataclass
class GroundTruth:
    """A `kinfu synth` ground_truth/ folder, read back. Meshes are loaded on demand.

    changes/objects/table/camera: as in changes.json; K (3,3), width, height; stamps_ns (N,) and poses (N,4,4) from
    camera_poses.txt (true camera-to-world); info: the whole changes.json.
    """

    folder: Path
    info: dict
    K: np.ndarray
    width: int
    height: int
    stamps_ns: np.ndarray
    poses: np.ndarray

    @property
    def changes(self) -> list[dict]:
        return self.info["changes"]

    @property
    def objects(self) -> list[dict]:
        return self.info.get("objects", [])

    @property
    def change_positions(self) -> np.ndarray:
        """(M, 3) true change positions (object centres)."""
        return np.array([c["position"] for c in self.changes], dtype=float).reshape(-1, 3)

    def mesh(self, state: str = "after"):
        """The true scene mesh, state "before" or "after" (open3d TriangleMesh with vertex colours)."""
        if state not in ("before", "after"):
            raise ConfigError(f"ground-truth state {state!r}: expected before or after")
        path = self.folder / f"scene_{state}.ply"
        if not path.exists() and (self.folder / "scene.ply").exists():
            path = self.folder / "scene.ply"  # a static scene (the room): one mesh for both states
        return _read_mesh(path)

    def object_meshes(self) -> dict:
        """{id: TriangleMesh} of the after state, including "table" and "floor"."""
        return {p.stem: _read_mesh(p) for p in sorted((self.folder / "objects").glob("*.ply"))}

    def hand(self) -> Trajectory:
        """The hand trajectory from hand.traj, in `world`, t in seconds after t0_ns (as on /hand/pose)."""
        tr = read_polhemus(self.folder / "hand.traj")
        start = float(self.info.get("hand", {}).get("start_time", 0.0))
        return Trajectory(tr.t + start, tr.positions, tr.rotations, frame=WORLD_FRAME, source=str(tr.source),
                          t0_ns=int(self.info.get("t0_ns", 0)), meta=dict(tr.meta))


def load_ground_truth(folder: str | os.PathLike) -> GroundTruth:
    """Read a ground_truth/ folder written by `kinfu synth` (or the recording folder holding it)."""
    folder = Path(folder)
    if (folder / "ground_truth" / "changes.json").exists():
        folder = folder / "ground_truth"
    path = folder / "changes.json"
    if not path.exists():
        raise RecordingError(f"{folder}: no changes.json (expected a `kinfu synth` ground_truth folder)")
    try:
        info = json.loads(path.read_text())
        K, width, height = _check_info(info)
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:
        raise RecordingError(f"{path}: not a kinfu synth changes.json ({exc})") from None
    poses_path = folder / "camera_poses.txt"
    if not poses_path.exists():
        raise RecordingError(f"{folder}: no camera_poses.txt (expected a `kinfu synth` ground_truth folder)")
    stamps, poses = [], []
    for lineno, line in enumerate(poses_path.read_text().splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        parts = line.split()
        try:
            sec, _, frac = parts[0].partition(".")
            stamp = int(sec) * 1_000_000_000 + int((frac + "000000000")[:9])
            T = np.array([float(v) for v in parts[1:]]).reshape(4, 4)
        except ValueError:
            raise RecordingError(f"{poses_path}: line {lineno} is not 'stamp_s' and 16 numbers") from None
        if not np.all(np.isfinite(T)):
            raise RecordingError(f"{poses_path}: line {lineno} has a pose that is not finite")
        stamps.append(stamp)
        poses.append(T)
    return GroundTruth(folder, info, K, width, height, np.array(stamps, dtype=np.int64),
                       np.array(poses, dtype=float).reshape(-1, 4, 4))


def _check_info(info: object) -> tuple[np.ndarray, int, int]:
    """K, width, height of a changes.json document; ValueError / KeyError / TypeError when it or the parts the
    evaluations read (changes, objects, table) are not what `kinfu synth` writes (a K of zeros gave numpy
    warnings and NaN scores, a string for "objects" an AttributeError)."""
    if not isinstance(info, dict):
        raise ValueError("not a JSON object")
    cam = info["camera"]
    K = np.asarray(cam["K"], dtype=float).reshape(3, 3)
    width, height = cam["width"], cam["height"]
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"camera K {K.reshape(-1).tolist()} has no positive finite focal lengths")
    if any(isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 16384 for v in (width, height)):
        raise ValueError(f"camera image size {width!r} x {height!r} is not 1..16384 pixels")
    for c in info["changes"]:
        pos = np.asarray(c["position"], dtype=float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ValueError("a change position is not [x, y, z] (three finite numbers)")
    objects = info.get("objects", [])
    if not isinstance(objects, list) or not all(isinstance(o, dict) and "id" in o for o in objects):
        raise ValueError("'objects' is not a list of objects with an 'id'")
    ids = [json.dumps(o["id"]) for o in objects]
    if len(set(ids)) != len(ids):  # each would be measured and counted twice
        raise ValueError(f"object ids repeat ({', '.join(sorted({i for i in ids if ids.count(i) > 1}))})")
    table = info.get("table", {})
    if not isinstance(table, dict) or not isinstance(info.get("frames", {}), dict):
        raise ValueError("'table' or 'frames' is not an object")
    for key, n in (("center", 2), ("size", 2), ("top_z", 1)):
        try:
            ok = key not in table or np.asarray(table[key], dtype=float).reshape(-1).shape == (n,)
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"table {key} is {table[key]!r}, expected {n} number(s)")
    _check_numbers(info, table)
    return K, width, height


def _is_int(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_numbers(info: dict, table: dict) -> None:
    """The numbers the evaluations take from changes.json without a default of their own: frame counts, t0_ns,
    the hand's start time, the table plane, the objects' centres (a string or NaN there was a traceback or a
    numpy warning, or an object reported as not reconstructed)."""
    for key, v in info.get("frames", {}).items():
        if key == "rate_hz":
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
                raise ValueError(f"frames rate_hz is {v!r}, expected a positive rate")
        elif v is not None and (not _is_int(v) or v < 0):  # count, scan, after, first_after (null: not split)
            raise ValueError(f"frames {key} is {v!r}, expected a count of frames")
    if "t0_ns" in info and not _is_int(info["t0_ns"]):
        raise ValueError(f"t0_ns is {info['t0_ns']!r}, expected integer nanoseconds")
    hand = info.get("hand", {})
    start = hand.get("start_time", 0.0) if isinstance(hand, dict) else None
    if isinstance(start, bool) or not isinstance(start, (int, float)) or not np.isfinite(start):
        raise ValueError(f"hand start_time is {start!r}, expected seconds" if isinstance(hand, dict)
                         else "'hand' is not an object")
    if "plane" in table:
        plane = np.asarray(table["plane"], dtype=float).reshape(-1)
        if plane.shape != (4,) or not np.all(np.isfinite(plane)) or not np.linalg.norm(plane[:3]) > 0:
            raise ValueError(f"table plane is {table['plane']!r}, expected a, b, c, d with a non-zero normal")
    for o in info.get("objects", []):
        for key in ("center", "center_before"):
            if key in o:
                c = np.asarray(o[key], dtype=float).reshape(-1)
                if c.shape != (3,) or not np.all(np.isfinite(c)):
                    raise ValueError(f"object {o['id']!r} {key} is {o[key]!r}, expected three finite numbers")


def _read_mesh(path: Path) -> o3d.geometry.TriangleMesh:
    if not path.exists():
        raise RecordingError(f"{path}: missing ground-truth mesh")
    # no reader chatter (open3d warnings, RPly's own lines on a damaged PLY): we report problems
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error), c_stderr_silenced():
        mesh = o3d.io.read_triangle_mesh(str(path))
    if len(mesh.triangles) == 0:
        raise RecordingError(f"{path}: not a triangle mesh (no triangles)")
    if (outside := faces_outside_vertices(len(mesh.vertices), np.asarray(mesh.triangles))) is not None:
        raise RecordingError(f"{path}: {outside}")
    return mesh
