"""A tiny synthetic arm-camera recording written with the project's writers, shared by the io tests."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.io.writers import RecordingWriter

S = 1_000_000_000
T0 = 1_600_000_000 * S
W, H = 20, 16
K = np.array([[30.0, 0, 9.5], [0, 30.0, 7.5], [0, 0, 1]])
T_WORLD_BASE = np.eye(4)
T_WORLD_BASE[:3, 3] = [0.0, 0.0, 0.7]
T_WRIST_CAM = np.eye(4)
T_WRIST_CAM[:3, :3] = Rotation.from_rotvec([0, 0, np.pi / 2]).as_matrix()
T_WRIST_CAM[:3, 3] = [0.05, 0.0, 0.1]


def T_base_wrist(t_s: float) -> np.ndarray:
    """Constant angular and linear velocity: slerp + linear interpolation reproduce it exactly."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.array([0.1, 0.5, 0.2]) * t_s).as_matrix()
    T[:3, 3] = [0.3 + 0.1 * t_s, -0.2 * t_s, 0.5]
    return T


def depth_mm(i: int) -> np.ndarray:
    d = (800 + 10 * i + np.arange(W * H).reshape(H, W)).astype(np.uint16)
    d[0, :3] = 0  # invalid pixels stay invalid
    return d


def color(i: int) -> np.ndarray:
    return np.full((H, W, 3), [i, 255 - i, 7], dtype=np.uint8)


def make_recording(path, n=12, fps=30.0, color_offset_ns=4_000_000, tf_from=0.0, info=True, color_every=1,
                   depth_encoding="16UC1", compressed=False, hand=False, info_size=(W, H)):
    """A tiny arm-camera recording: TF world -> base (static) -> wrist (100 Hz) -> camera_optical (static)."""
    with RecordingWriter(path) as w:
        w.write_tf(T0, [("world", "base_link", T_WORLD_BASE), ("wrist", "camera_optical", T_WRIST_CAM)],
                   static=True)
        events = []
        for k in range(int((n / fps + 0.2) * 100)):
            t = tf_from + k / 100
            events.append((T0 + int(round(t * S)), "tf", k))
        for i in range(n):
            t = T0 + int(round(i / fps * S)) + 50_000_000
            events.append((t, "depth", i))
            if i % color_every == 0:
                events.append((t + color_offset_ns, "color", i))
        for stamp, kind, i in sorted(events, key=lambda e: (e[0], e[1])):
            if kind == "tf":
                w.write_tf(stamp, [("base_link", "wrist", T_base_wrist((stamp - T0) / S))])
                if hand:
                    Th = np.eye(4)
                    Th[:3, 3] = [0.1 * i / 100, 0.2, 0.3]
                    w.write_pose("/hand/pose", stamp, "world", Th)
            elif kind == "depth":
                if compressed:
                    w.write_compressed_depth("/camera/depth/image_raw/compressedDepth", stamp, "camera_optical",
                                             depth_mm(i))
                elif depth_encoding == "16UC1":
                    w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i), "16UC1")
                elif depth_encoding == "32FC1":
                    w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i) / 1000.0,
                                  "32FC1")
                else:  # something we cannot read as depth
                    w.write_image("/camera/depth/image_raw", stamp, "camera_optical",
                                  depth_mm(i).astype(np.uint8), "mono8")
                if info:
                    w.write_camera_info("/camera/depth/camera_info", stamp, "camera_optical", K, *info_size)
            else:
                w.write_image("/camera/color/image_raw", stamp, "camera_optical", color(i), "rgb8")
    return path


def expected_pose(stamp_ns: int) -> np.ndarray:
    return T_WORLD_BASE @ T_base_wrist((stamp_ns - T0) / S) @ T_WRIST_CAM


def read_frames(path, **kw) -> tuple[list, "FrameStats"]:
    """iter_frames of a recording without camera poses (its keywords passed on): the frames and their FrameStats."""
    from kinfu_cli.io.frames import FrameStats, iter_frames
    from kinfu_cli.io.recording import open_recording

    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, pose_source="none", stats=stats, **kw))
    return frames, stats


# 30 Hz colour and late-logged depth on an 8x6 camera (the pairing tests of io/frames' colour look-ahead)
LATE_T0 = 1_700_000_000 * S
LATE_PERIOD = 33_333_333
LATE_W, LATE_H = 8, 6
LATE_K = np.array([[10.0, 0, 3.5], [0, 10.0, 2.5], [0, 0, 1]])


def late_colour(k: int) -> np.ndarray:
    """Colour image k of write_logged: red k % 256."""
    return np.full((LATE_H, LATE_W, 3), [k % 256, 200, 7], np.uint8)


def write_logged(path, events):
    """A recording of `events` (log ns, "colour" | "depth", k): image k stamped LATE_T0 + k * LATE_PERIOD and logged
    at its log ns; colour k is late_colour(k), depth k reads 1000 + k mm, with its camera info logged with it."""
    with RecordingWriter(path) as w:
        for log_ns, kind, k in sorted(events):
            stamp = LATE_T0 + k * LATE_PERIOD
            if kind == "colour":
                w.write_image("/camera/color/image_raw", stamp, "cam", late_colour(k), "rgb8", log_ns=log_ns)
                continue
            w.write_image("/camera/depth/image_raw", stamp, "cam", np.full((LATE_H, LATE_W), 1000 + k, np.uint16),
                          "16UC1", log_ns=log_ns)
            w.write_camera_info("/camera/depth/camera_info", stamp, "cam", LATE_K, LATE_W, LATE_H, log_ns=log_ns)
    return path
