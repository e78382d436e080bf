"""Frame assembly: depth images paired with the nearest colour image and the camera pose at the depth stamp.

`iter_frames` streams the depth, colour and camera-info topics once, in log order, keeping only the few
messages still waiting for a partner, so memory does not grow with the recording. Stamps are the header
stamps of the images (the log time where a header stamp is zero). Frames that cannot be used are counted
by reason in a `FrameStats`, which the fusion report prints.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.errors import ConfigError, RecordingError, TransformError
from kinfu_cli.io.messages import (POSE_TYPES, camera_info_K, decode_color, decode_depth, header_frame,
                                   header_stamp_ns, normalize_msgtype, pose_message_to_matrix)
from kinfu_cli.io.roles import Roles, detect_roles
from kinfu_cli.io.tf_buffer import TfBuffer

POSE_SOURCES = ("tf", "topic", "none")

DROP_NO_POSE = "no camera pose within the TF range"
DROP_NO_POSE_TOPIC = "no pose message within tolerance"
DROP_EMPTY = "depth image has no valid pixel"
DROP_NO_COLOR = "no colour image within tolerance"


@dataclass
class RGBDFrame:
    """One depth frame. index: position of the depth message on its topic among those read (0-based;
    counted from the start of the time window minus the tolerance when start_s is given)."""

    index: int
    stamp_ns: int
    depth: np.ndarray  # float32 (H, W) metres, 0 = invalid
    color: np.ndarray | None  # uint8 (H, W, 3) RGB, or None
    K: np.ndarray  # (3, 3) of the depth camera
    T_world_camera: np.ndarray | None  # (4, 4) camera-to-world, or None with pose_source="none"


@dataclass
class FrameStats:
    """How many depth frames were used, skipped by --every / time window, and dropped (reason -> count)."""

    depth_messages: int = 0
    used: int = 0
    skipped: int = 0
    without_color: int = 0
    dropped: dict[str, int] = field(default_factory=dict)

    def drop(self, reason: str) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def as_dict(self) -> dict:
        return {"depth_messages": self.depth_messages, "used": self.used, "skipped": self.skipped,
                "without_color": self.without_color, "dropped": dict(self.dropped),
                "dropped_total": self.dropped_total}


def _stamp(msg: object, log_ns: int) -> int:
    s = header_stamp_ns(msg)
    return s if s is not None else int(log_ns)


class _PosePath:
    """Camera poses from a pose topic (PoseStamped, Odometry, ...), interpolated like a TF link."""

    def __init__(self, rec, topic: str, tolerance_ns: int):
        info = rec.require_topic(topic, "pose topic")
        wrong = [t for t in (info.msgtypes or [info.msgtype]) if normalize_msgtype(t) not in POSE_TYPES]
        if wrong:
            raise RecordingError(f"{rec.path}: pose topic {topic} carries {', '.join(wrong)}; expected one of "
                                 f"{', '.join(POSE_TYPES)}")
        self.tf = TfBuffer()
        self.frame = None
        for _, msgtype, log_ns, msg in rec.typed_messages([topic]):
            T = pose_message_to_matrix(msg, msgtype)
            frame = header_frame(msg).lstrip("/") or "world"
            if self.frame is None:
                self.frame = frame
            elif frame != self.frame:  # poses in two frames cannot be interpolated into one trajectory
                raise RecordingError(f"{rec.path}: pose topic {topic} changes frame_id from {self.frame!r} to "
                                     f"{frame!r} at stamp {_stamp(msg, log_ns)} ns; expected one frame")
            self.tf.add(self.frame, "__camera__", _stamp(msg, log_ns), T)
        if self.frame is None:
            raise RecordingError(f"{rec.path}: pose topic {topic} has no messages")
        self.tolerance_ns = tolerance_ns

    def pose(self, stamp_ns: int) -> np.ndarray:
        return self.tf.lookup(self.frame, "__camera__", stamp_ns, tolerance_ns=self.tolerance_ns)


def iter_frames(rec, roles: Roles | None = None, pose_source: str = "tf", pose_topic: str | None = None,
                tolerance_s: float = 0.05, start_s: float | None = None, end_s: float | None = None,
                every: int = 1, stats: FrameStats | None = None, tf: TfBuffer | None = None,
                require_color: bool = False) -> Iterator[RGBDFrame]:
    """Yield RGBDFrames of a Recording.

    pose_source: "tf" (world_frame <- camera_frame from /tf, /tf_static), "topic" (a pose topic giving
    T_world_camera, `pose_topic`), or "none". start_s/end_s: seconds from the start of the recording.
    every: keep every n-th depth frame. tolerance_s: largest |t_colour - t_depth| for a pair, and how far
    a pose may be extrapolated beyond the TF / pose range. Frames without colour are kept (color=None)
    unless require_color. `stats` (a FrameStats) is filled in while streaming.
    """
    if pose_source not in POSE_SOURCES:
        raise ConfigError(f"--pose-source {pose_source!r}: expected one of {', '.join(POSE_SOURCES)}")
    if every < 1:
        raise ConfigError(f"--every {every}: expected an integer >= 1")
    if tolerance_s < 0:
        raise ConfigError(f"--tolerance {tolerance_s}: expected a value >= 0 seconds")
    stats = stats if stats is not None else FrameStats()
    if roles is None:
        if tf is None and pose_source == "tf":
            tf = TfBuffer.from_recording(rec)
        roles = detect_roles(rec, tf=tf)
    depth_topic = roles.depth_topic
    if depth_topic is None:
        avail = ", ".join(f"{n} ({i.msgtype})" for n, i in rec.topics.items()) or "none"
        raise RecordingError(f"{rec.path}: no depth image topic found (set --depth-topic); topics: {avail}")
    rec.require_topic(depth_topic, "depth topic")
    if roles.info_topic is None:
        raise RecordingError(f"{rec.path}: no sensor_msgs/CameraInfo topic for depth topic {depth_topic} "
                             f"(intrinsics are needed; set --info-topic)")
    rec.require_topic(roles.info_topic, "camera info topic")
    color_topic = roles.color_topic
    if color_topic is not None:
        rec.require_topic(color_topic, "colour topic")
    tol_ns = int(round(tolerance_s * 1e9))

    first_info = rec.first_message(roles.info_topic)
    if first_info is None:
        raise RecordingError(f"{rec.path}: camera info topic {roles.info_topic} has no messages")
    K, info_w, info_h = camera_info_K(first_info, roles.info_topic)

    pose_fn = None
    if pose_source == "tf":
        tf = tf if tf is not None else TfBuffer.from_recording(rec)
        camera = roles.camera_frame
        if camera is None:
            first_depth = rec.first_message(depth_topic)
            camera = header_frame(first_depth).lstrip("/") if first_depth is not None else ""
        if not camera:
            raise RecordingError(f"{rec.path}: depth topic {depth_topic} has no header frame_id; "
                                 f"set --camera-frame")
        world = roles.world_frame
        if world is None:
            raise TransformError(f"{rec.path}: no TF world frame found for camera frame {camera!r} "
                                 f"(no /tf data?); set --world-frame or --pose-source none")
        try:
            tf.require_chain(world, camera)  # a missing link fails now, naming both frames
        except TransformError as exc:
            raise TransformError(f"{rec.path}: {exc} (set --camera-frame / --world-frame)") from None

        def pose_fn(stamp_ns: int) -> np.ndarray | None:
            try:
                return tf.lookup(world, camera, stamp_ns, tolerance_ns=tol_ns)
            except TransformError:
                stats.drop(DROP_NO_POSE)
                return None
    elif pose_source == "topic":
        if pose_topic is None:
            raise ConfigError("--pose-source topic needs --pose-topic (a PoseStamped/Odometry/... topic)")
        path = _PosePath(rec, pose_topic, tol_ns)

        def pose_fn(stamp_ns: int) -> np.ndarray | None:
            try:
                return path.pose(stamp_ns)
            except TransformError:
                stats.drop(DROP_NO_POSE_TOPIC)
                return None

    t0 = rec.start_ns or 0
    start_ns = None if start_s is None else t0 + int(start_s * 1e9)
    end_ns = None if end_s is None else t0 + int(end_s * 1e9)
    if start_ns is not None and end_ns is not None and end_ns < start_ns:
        raise ConfigError(f"--start {start_s} s is after --end {end_s} s")
    read_start = None if start_ns is None else max(0, start_ns - tol_ns)
    read_end = None if end_ns is None else end_ns + tol_ns

    topics = [depth_topic, roles.info_topic] + ([color_topic] if color_topic else [])
    pending: deque[tuple[int, int, object]] = deque()  # (index, stamp, depth msg)
    colors: deque[tuple[int, object]] = deque()  # (stamp, colour msg), decoded only when paired
    state = {"K": K, "w": info_w, "h": info_h, "n": 0, "index": 0}

    def emit(index: int, stamp: int, msg: object) -> RGBDFrame | None:
        depth = decode_depth(msg, depth_topic)
        h, w = depth.shape
        if state["w"] and state["h"] and (w, h) != (state["w"], state["h"]):
            raise RecordingError(f"{rec.path}: depth image on {depth_topic} is {w}x{h} but camera info "
                                 f"{roles.info_topic} says {state['w']}x{state['h']}")
        T = None
        if pose_fn is not None:
            T = pose_fn(stamp)
            if T is None:
                return None
        if not np.any(depth > 0):
            stats.drop(DROP_EMPTY)
            return None
        color = None
        if color_topic is not None and colors:
            best_stamp, best = min(colors, key=lambda c: abs(c[0] - stamp))
            if abs(best_stamp - stamp) <= tol_ns:
                color = decode_color(best, color_topic)
        if color is None:
            if require_color:
                stats.drop(DROP_NO_COLOR)
                return None
            stats.without_color += 1
        stats.used += 1
        return RGBDFrame(index=index, stamp_ns=stamp, depth=depth, color=color, K=state["K"].copy(),
                         T_world_camera=T)

    def prune(before: int) -> None:
        while colors and colors[0][0] < before - tol_ns:
            colors.popleft()

    def flush(up_to: int | None) -> Iterator[RGBDFrame]:
        """Emit pending depth frames whose colour partner can no longer arrive (all when up_to is None)."""
        while pending and (up_to is None or pending[0][1] + tol_ns < up_to):
            index, stamp, msg = pending.popleft()
            frame = emit(index, stamp, msg)
            if frame is not None:
                yield frame
            prune(pending[0][1] if pending else stamp)

    for topic, log_ns, msg in rec.messages(topics, start_ns=read_start, end_ns=read_end):
        if topic == roles.info_topic:
            K_new, w_new, h_new = camera_info_K(msg, roles.info_topic)
            state.update(K=K_new, w=w_new, h=h_new)
            continue
        stamp = _stamp(msg, log_ns)
        if topic == color_topic:
            colors.append((stamp, msg))
            yield from flush(stamp)
            if not pending:
                prune(stamp)
            continue
        # a depth message
        index = state["index"]
        state["index"] += 1
        if (start_ns is not None and stamp < start_ns) or (end_ns is not None and stamp > end_ns):
            continue  # read only for the tolerance margin of the time window
        stats.depth_messages += 1
        if state["n"] % every:
            state["n"] += 1
            stats.skipped += 1
            continue
        state["n"] += 1
        pending.append((index, stamp, msg))
        if color_topic is None:
            yield from flush(None)
        elif len(pending) > 64:  # colour stream stalled: do not hold depth frames forever
            index, stamp, msg = pending.popleft()
            frame = emit(index, stamp, msg)
            if frame is not None:
                yield frame
    yield from flush(None)


# ------------------------------------------------------------------------------------------- CLI options
FRAME_OPTIONS = ("pose_source", "pose_topic", "tolerance_s", "start_s", "end_s", "every")


def frame_options(func):
    """click decorator adding --pose-source, --pose-topic, --tolerance, --start, --end, --every; hand the
    values to iter_frames with `iter_frames(rec, roles, **frame_kwargs(kwargs))`."""
    import click

    opts = [
        click.option("--pose-source", "pose_source", type=click.Choice(list(POSE_SOURCES)), default="tf",
                     show_default=True, help="Camera poses from TF (world frame <- camera frame), a pose topic, "
                                             "or none."),
        click.option("--pose-topic", "pose_topic", default=None, metavar="TOPIC",
                     help="Camera pose topic (PoseStamped, Odometry, ...) for --pose-source topic."),
        click.option("--tolerance", "tolerance_s", default=0.05, show_default=True, type=float,
                     help="Largest depth/colour stamp difference, and how far a pose may be extrapolated (s)."),
        click.option("--start", "start_s", default=None, type=float, help="Start, seconds from the recording start."),
        click.option("--end", "end_s", default=None, type=float, help="End, seconds from the recording start."),
        click.option("--every", "every", default=1, show_default=True, type=int,
                     help="Use every n-th depth frame."),
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


def frame_kwargs(kwargs: dict) -> dict:
    """Pop the frame options out of a command's kwargs (for iter_frames)."""
    return {name: kwargs.pop(name) for name in FRAME_OPTIONS if name in kwargs}
