"""A room-scale synthetic sequence: a handheld camera walks a loop through a furnished room.

`make_room(seed, ...)` builds a `RoomScenario`: a 5 x 4 m floor, four 2.5 m walls (a door gap in one), a table,
a sofa and a shelf, and a camera about 1.5 m above the floor that walks an ellipse around the room centre while
looking across the room (down at the floor, level, up at the wall tops in turn). There is no robot arm and no
hand: the TF is `world -> camera_optical` directly. `world` is "z-up" (REP-103) or "y-down" (the whole room and
every pose rotated +90 degrees about x, so up is -y); the recording declares the up direction on
/kinfu/world_up either way. Frames are rendered with the same `DepthSensor` as the tabletop scenario.

`write_room_recordings(room, paths, ...)` streams the frames into MCAP / ROS 1 bag / ROS 2 bag at once;
`write_room_ground_truth(room, folder)` writes scene.ply (in the recording's world), changes.json (no changes;
the camera, the room extent and the up direction) and camera_poses.txt, readable by `load_ground_truth`.
"""

from __future__ import annotations

import os
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d

from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.poses import look_at
from kinfu_cli.core.progress import progress
from kinfu_cli.io.world_up import WORLD_UP_TOPIC
from kinfu_cli.io.writers import RecordingWriter
from kinfu_cli.sim.robot import CAMERA_FRAME, WORLD_FRAME
from kinfu_cli.sim.scene import FLOOR_COLOUR, PALETTE, TABLE_COLOUR
from kinfu_cli.sim.scenario import MAX_FRAME_RATE_HZ, MIN_FRAME_RATE_HZ, depth_to_mm
from kinfu_cli.sim.sensor import DepthSensor, SensorFrame, kinect_v1_intrinsics, mesh_target

WORLDS = ("z-up", "y-down")
ROOM_SIZE = (5.0, 4.0, 2.5)  # interior x, y extent and wall height (m); the floor's top is at z = 0
WALL_THICKNESS = 0.1
DOOR = (0.6, 1.5, 2.0)  # door gap in the +y wall: x from 0.6 to 1.5 m, 2.0 m high
CAMERA_HEIGHT = 1.5
WALL_COLOUR = np.array([0.85, 0.82, 0.75])
MAX_RANGE = 7.0  # the far wall is up to ~6.4 m away
# labels.ply / changes.json "labels": a part's object is its name before "_" (the table's top and legs are one
# table); floor, walls and lintel are the background (0)
ROOM_OBJECTS = ("table", "sofa", "shelf")
LABELS_SPACING = 0.01  # labels.ply: one labelled point per 1 cm x 1 cm of the room's visible surface


def world_rotation(world: str) -> np.ndarray:
    """4x4 rotation from the z-up room frame into the recording's world (identity, or +90 deg about x: up -> -y)."""
    if world not in WORLDS:
        raise ConfigError(f"expected one of {', '.join(WORLDS)}, got {world!r}", parameter="world")
    W = np.eye(4)
    if world == "y-down":
        W[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]
    return W


@dataclass
class RoomFrame:
    """One frame: index, stamp (ns), the camera pose in the z-up room frame and in the recording's world."""

    index: int
    stamp_ns: int
    T_room_camera: np.ndarray
    T_world_camera: np.ndarray


@dataclass
class RoomScenario:
    """The room sequence in memory. `parts` are (name, extents, centre) boxes in the z-up room frame."""

    seed: int
    world: str
    width: int
    height: int
    K: np.ndarray
    sensor: DepthSensor
    parts: list[tuple[str, tuple, tuple, np.ndarray]]
    frames: list[RoomFrame]
    W: np.ndarray
    kind: str = "room"
    hand: list = field(default_factory=list)
    changes: list = field(default_factory=list)
    meta: dict = field(default_factory=dict)
    _mesh: o3d.geometry.TriangleMesh | None = None
    _target: object = None

    @property
    def up(self) -> np.ndarray:
        """The up direction in the recording's world."""
        return self.W[:3, :3] @ np.array([0.0, 0.0, 1.0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the true geometry (walls, floor slab) in the recording's world."""
        v = np.asarray(self.mesh(world=True).vertices)
        return v.min(axis=0), v.max(axis=0)

    def mesh(self, world: bool = False) -> o3d.geometry.TriangleMesh:
        """The room as one coloured mesh, in the z-up room frame or (world=True) in the recording's world."""
        if self._mesh is None:
            out = o3d.geometry.TriangleMesh()
            for _, ext, ctr, colour in self.parts:
                m = o3d.geometry.TriangleMesh.create_box(*ext)
                m.translate(np.asarray(ctr) - np.asarray(ext) / 2)
                m.paint_uniform_color(colour)
                out += m
            out.compute_vertex_normals()
            self._mesh = out
        m = o3d.geometry.TriangleMesh(self._mesh)
        if world:
            m.transform(self.W)
        return m

    def textured_target(self):
        """The room for the sensor with texture (a RaycastTarget, z-up room frame): the floor's checker, a wallpaper
        pattern on the walls and furniture. The plain room (`mesh`, what `render` shows) has one colour per part, so
        a tracker that reads colour has nothing to hold on to there; real rooms have texture."""
        from kinfu_cli.sim.scene import RaycastTarget

        rc = o3d.t.geometry.RaycastingScene()
        labels, albedo, textured = [], [], []
        for name, ext, ctr, colour in self.parts:
            m = o3d.geometry.TriangleMesh.create_box(*ext)
            m.translate(np.asarray(ctr) - np.asarray(ext) / 2)
            rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(m))
            labels.append(room_label(name))
            albedo.append(np.asarray(colour, dtype=float))
            textured.append(2 if name == "floor" else 4)
        return RaycastTarget(rc, np.asarray(labels, np.int32), np.asarray(albedo), np.asarray(textured, np.int32))

    def part_distances(self, points: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """(label, signed distance) of each part box to world points (N, 3): 0 background, 1.. ROOM_OBJECTS."""
        from kinfu_cli.sim.scene import _box_sdf  # the box distance the tabletop scenes use

        q = np.asarray(points, dtype=np.float64) @ self.W[:3, :3]  # world -> z-up room frame (W is a rotation)
        return [(room_label(name), _box_sdf(q - np.asarray(ctr), np.asarray(ext) / 2))
                for name, ext, ctr, _ in self.parts]

    def label_cloud(self, spacing: float = LABELS_SPACING) -> tuple[np.ndarray, np.ndarray]:
        """Labelled surface points (world (N, 3), labels (N,)) of the parts: each box's faces sampled every
        `spacing`, minus points inside another part (a leg's foot in the floor, wall ends in each other)."""
        from kinfu_cli.sim.sampling import sample_surface

        pts, lab = [], []
        for k, (name, ext, ctr, _) in enumerate(self.parts):
            box = o3d.geometry.TriangleMesh.create_box(*ext).translate(np.asarray(ctr) - np.asarray(ext) / 2)
            p, _ = sample_surface(np.asarray(box.vertices), np.asarray(box.triangles), spacing, seed=self.seed + k)
            pts.append(p @ self.W[:3, :3].T)
            lab.append(np.full(len(p), room_label(name), dtype=np.int64))
        pts, lab = np.concatenate(pts), np.concatenate(lab)
        inside = np.min([d for _, d in self.part_distances(pts)], axis=0) < -1e-3
        return pts[~inside], lab[~inside]

    def render(self, i: int) -> SensorFrame:
        """Frame i (rendered in the room frame: the images do not depend on the world convention)."""
        if self._target is None:
            self._target = mesh_target(self.mesh())
        return self.sensor.render_frame(self._target, self.frames[i].T_room_camera, frame_seed=i)


def room_label(part_name: str) -> int:
    """The object label of a room part (ROOM_OBJECTS order from 1; 0 for floor, walls, lintel)."""
    name = part_name.split("_")[0]
    return ROOM_OBJECTS.index(name) + 1 if name in ROOM_OBJECTS else 0


def room_parts(seed: int = 0) -> list[tuple[str, tuple, tuple, np.ndarray]]:
    """Boxes (name, extents, centre, colour) of the room in the z-up room frame centred on the floor's middle."""
    sx, sy, h = ROOM_SIZE
    t = WALL_THICKNESS
    hx, hy = sx / 2, sy / 2
    d0, d1, dh = DOOR
    parts = [("floor", (sx + 2 * t, sy + 2 * t, 0.05), (0.0, 0.0, -0.025), FLOOR_COLOUR),
             ("wall_-x", (t, sy + 2 * t, h), (-hx - t / 2, 0.0, h / 2), WALL_COLOUR),
             ("wall_+x", (t, sy + 2 * t, h), (hx + t / 2, 0.0, h / 2), WALL_COLOUR),
             ("wall_-y", (sx, t, h), (0.0, -hy - t / 2, h / 2), WALL_COLOUR),
             # +y wall with a door gap from x = d0 to d1 (a lintel above it)
             ("wall_+y_a", (d0 + hx, t, h), ((-hx + d0) / 2, hy + t / 2, h / 2), WALL_COLOUR),
             ("wall_+y_b", (hx - d1, t, h), ((d1 + hx) / 2, hy + t / 2, h / 2), WALL_COLOUR),
             ("lintel", (d1 - d0, t, h - dh), ((d0 + d1) / 2, hy + t / 2, (h + dh) / 2), WALL_COLOUR)]
    # table: 1.0 x 0.7 top at 0.75 m, four legs
    tx, ty = -0.9 + 0.1 * (seed % 3), 0.3
    parts.append(("table_top", (1.0, 0.7, 0.04), (tx, ty, 0.73), TABLE_COLOUR))
    for i, (lx, ly) in enumerate([(-0.45, -0.3), (0.45, -0.3), (-0.45, 0.3), (0.45, 0.3)]):
        parts.append((f"table_leg{i + 1}", (0.05, 0.05, 0.71), (tx + lx, ty + ly, 0.355), TABLE_COLOUR))
    # sofa against the -y wall: seat and backrest
    parts.append(("sofa_seat", (2.0, 0.9, 0.45), (0.4, -hy + 0.45, 0.225), PALETTE[0]))
    parts.append(("sofa_back", (2.0, 0.2, 0.85), (0.4, -hy + 0.1, 0.425), PALETTE[0]))
    # shelf against the +x wall
    parts.append(("shelf", (0.4, 1.2, 1.8), (hx - 0.2, 0.6, 0.9), PALETTE[2]))
    return [(n, tuple(float(e) for e in ext), tuple(float(c) for c in ctr), np.asarray(col, dtype=float))
            for n, ext, ctr, col in parts]


def make_room(seed: int = 0, world: str = "z-up", width: int = 160, height: int = 120, frames: int = 30,
              noise: bool = True, frame_rate_hz: float = 5.0, t0_ns: int = 1_767_225_600_000_000_000
              ) -> RoomScenario:
    """Build the room sequence: `frames` views along one loop (at least 3)."""
    W = world_rotation(world)
    if frames < 3:
        raise ConfigError(f"expected at least 3 frames for the room loop, got {frames}", parameter="frames")
    if width < 8 or height < 6 or width > 4096 or height > 4096:
        raise ConfigError(f"expected 8x6 to 4096x4096 pixels, got {width}x{height}", parameter="width/height")
    check_number(frame_rate_hz, "frame_rate_hz", MIN_FRAME_RATE_HZ, MAX_FRAME_RATE_HZ, unit="Hz")
    rng = np.random.default_rng([seed, 23])
    k = np.arange(frames)
    a = 2 * np.pi * k / frames + rng.uniform(0, 2 * np.pi)
    eyes = np.stack([1.2 * np.cos(a), 0.8 * np.sin(a),
                     CAMERA_HEIGHT + 0.05 * np.sin(3 * a) + rng.normal(0, 0.01, frames)], axis=1)
    look_az = a + np.pi + 0.8 * np.sin(2.0 * a)  # across the room, swinging left and right
    look_z = np.array([0.1, 1.2, 2.6])[k % 3]  # down at the floor, level, up at the wall tops
    targets = np.stack([2.0 * np.cos(look_az), 1.6 * np.sin(look_az), look_z], axis=1)
    stamps = t0_ns + np.round((0.5 + k / frame_rate_hz) * 1e9).astype(np.int64)
    cam = []
    for i in range(frames):
        T = look_at(eyes[i], targets[i])
        cam.append(RoomFrame(i, int(stamps[i]), T, W @ T))
    K = kinect_v1_intrinsics(width, height)
    sensor = DepthSensor(K, width, height, max_range=MAX_RANGE, noise=noise, seed=seed)
    return RoomScenario(seed, world, width, height, K, sensor, room_parts(seed), cam, W,
                        meta={"n_scan": frames, "n_after": 0, "frame_rate_hz": frame_rate_hz, "noise": noise,
                              "t0_ns": t0_ns})


def write_room_recordings(room: RoomScenario, paths: list[str | os.PathLike], topics: dict, depth_format: str = "png",
                          color_format: str = "jpeg", quiet: bool = True, jpeg_quality: int = 75,
                          camera_pose_topic: str | None = None) -> list[Path]:
    """Write the room into every path at once: /kinfu/world_up first, then per frame /tf world -> camera_optical,
    camera info, depth and colour (topics: role -> topic, as `recording_topics` gives them)."""
    t0 = room.frames[0].stamp_ns - 1
    with ExitStack() as stack:
        writers = [stack.enter_context(RecordingWriter(p)) for p in paths]
        for w in writers:
            w.write_vector(WORLD_UP_TOPIC, t0, WORLD_FRAME, room.up)
        for f in progress(room.frames, total=len(room.frames), desc="synth room", quiet=quiet, unit="frame"):
            fr = room.render(f.index)
            depth_mm = depth_to_mm(fr.depth)
            for w in writers:
                w.write_tf(f.stamp_ns, [(WORLD_FRAME, CAMERA_FRAME, f.T_world_camera)])
                if camera_pose_topic:
                    w.write_pose(camera_pose_topic, f.stamp_ns, WORLD_FRAME, f.T_world_camera)
                w.write_camera_info(topics["camera_info"], f.stamp_ns, CAMERA_FRAME, room.K, room.width, room.height)
                if depth_format == "png":
                    w.write_compressed_depth(topics["depth"], f.stamp_ns, CAMERA_FRAME, depth_mm)
                else:
                    w.write_image(topics["depth"], f.stamp_ns, CAMERA_FRAME, depth_mm, "16UC1")
                if color_format == "raw":
                    w.write_image(topics["color"], f.stamp_ns, CAMERA_FRAME, fr.color, "rgb8")
                else:
                    w.write_compressed_image(topics["color"], f.stamp_ns, CAMERA_FRAME, fr.color, fmt=color_format,
                                             quality=jpeg_quality)
    return [Path(p) for p in paths]


def write_room_ground_truth(room: RoomScenario, folder: str | os.PathLike, topics: dict) -> Path:
    """scene.ply (the room in the recording's world), changes.json, camera_poses.txt and labels.ply (per-point
    object labels of the visible surface, `label_cloud`; changes.json's "labels" names them), atomically.
    (Per-voxel labels cost the room's whole 70 m2 band of voxels, over a minute: `sim.voxel_labels` with
    `part_distances` makes them on demand.)"""
    from kinfu_cli.io.labelled_cloud import write_labelled_cloud

    lo, hi = room.bounds()
    with atomic_dir(folder) as tmp:
        write_labelled_cloud(tmp / "labels.ply", *room.label_cloud())
        m = room.mesh(world=True)
        if not o3d.io.write_triangle_mesh(str(tmp / "scene.ply"), m, write_ascii=False, compressed=False,
                                          write_vertex_normals=False, print_progress=False):
            raise ConfigError(f"{tmp / 'scene.ply'}: could not write the mesh")
        write_json(tmp / "changes.json", {
            "changes": [], "objects": [], "scenario": "room",
            "labels": {"0": "background", **{str(k + 1): n for k, n in enumerate(ROOM_OBJECTS)}},
            "seed": room.seed, "t0_ns": room.meta["t0_ns"],
            "world": room.world, "up": room.up.tolist(),
            "room": {"interior_size": list(ROOM_SIZE), "wall_thickness": WALL_THICKNESS,
                     "bounds_min": lo.tolist(), "bounds_max": hi.tolist(),
                     "parts": [{"name": n, "extents": list(e), "center": list(c)} for n, e, c, _ in room.parts],
                     "frame_of_parts": "z-up room frame; world = W @ room"},
            "world_from_room": room.W.tolist(),
            "camera": {"K": room.K.tolist(), "width": room.width, "height": room.height, "frame": CAMERA_FRAME,
                       "model": "kinect_v1 (fx = fy = 585 at 640x480)", "min_range": room.sensor.min_range,
                       "max_range": room.sensor.max_range, "noise": room.meta["noise"]},
            "frames": {"count": len(room.frames), "rate_hz": room.meta["frame_rate_hz"]},
            "frames_tree": {"world_frame": WORLD_FRAME, "camera_frame": CAMERA_FRAME,
                            "chain": [WORLD_FRAME, CAMERA_FRAME]},
            "topics": topics,
        })
        lines = ["# stamp_s (Unix seconds of the depth message) then the true T_world_camera, 16 numbers row-major"]
        for f in room.frames:
            lines.append(f"{f.stamp_ns // 1_000_000_000}.{f.stamp_ns % 1_000_000_000:09d} "
                         + " ".join(f"{v:.9f}" for v in f.T_world_camera.reshape(-1)))
        (tmp / "camera_poses.txt").write_text("\n".join(lines) + "\n")
    return Path(folder)
