"""Frame assembly: depth images paired with the nearest colour image and the camera pose at the depth stamp.

`iter_frames` finds the topics, the depth camera (camera info, or intrinsics fitted to an organized cloud), the
colour registration and the pose source (TF chain, pose topic or none), then streams the frames of the time window
through io.frame_pairing's FramePairer: partners are matched by stamp, not by log order, holding only the messages
that may still be a partner. Stamps are the header stamps of the images (the log time where a header stamp is
zero). Frames that cannot be used are counted by reason in a `FrameStats` (io.rgbd_frame), which the fusion
report prints.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import field, replace

import numpy as np

from kinfu_cli.core.camera import field_of_view_problem, intrinsics_matrix, scaled_intrinsics
from kinfu_cli.core.errors import ConfigError, RecordingError, TransformError
from kinfu_cli.io.camera_info import image_camera
from kinfu_cli.io.color_registration import check_color_size, color_registration
from kinfu_cli.io.frame_pairing import FramePairer, PoseLookup
from kinfu_cli.io.messages import (POSE_TYPES, decode_depth, header_frame, normalize_msgtype, pose_message_to_tq)
from kinfu_cli.io.pointcloud2 import (MAX_PINHOLE_RMS_PX, POINTCLOUD2, fit_intrinsics, has_color, is_cloud,
                                      organized_problem, pinhole_rms)
from kinfu_cli.io.realsense_bag import depth_units, is_sdk_stream, sdk_color_registration
from kinfu_cli.io.rgbd_frame import (DROP_CHAIN_BROKEN, DROP_NO_POSE, DROP_NO_POSE_TOPIC, FrameStats, RGBDFrame,
                                     message_stamp_ns)
from kinfu_cli.io.roles import Roles, detect_roles, require_role_topic, unorganized_clouds
from kinfu_cli.io.tf_buffer import TfBuffer
from kinfu_cli.io.undistort import Undistorter

POSE_SOURCES = ("tf", "topic", "none")
MAX_SECONDS = 1e7  # bound of times and tolerances (116 days): stamps in ns stay far inside int64

class _PosePath:
    """Camera poses from a pose topic (PoseStamped, Odometry, ...), interpolated like a TF link."""

    def __init__(self, rec, topic: str, tolerance_ns: int):
        info = rec.require_topic(topic, "pose topic")
        wrong = [t for t in (info.msgtypes or [info.msgtype]) if normalize_msgtype(t) not in POSE_TYPES]
        if wrong:
            raise RecordingError(f"{rec.path}: pose topic {topic} carries {', '.join(wrong)}; expected one of "
                                 f"{', '.join(POSE_TYPES)}")
        self.rec_path, self.topic = rec.path, topic
        self.tf = TfBuffer()
        self.frame = None
        for _, msgtype, log_ns, msg in rec.typed_messages([topic]):
            trans, quat = pose_message_to_tq(msg, msgtype)
            frame = header_frame(msg).lstrip("/") or "world"
            if self.frame is None:
                self.frame = frame
            elif frame != self.frame:  # poses in two frames cannot be interpolated into one trajectory
                raise RecordingError(f"{rec.path}: pose topic {topic} changes frame_id from {self.frame!r} to "
                                     f"{frame!r} at stamp {message_stamp_ns(msg, log_ns)} ns; expected one frame")
            try:  # the checks of a TF transform: finite, unit quaternion, within reach
                self.tf.add_quat(self.frame, "__camera__", message_stamp_ns(msg, log_ns), trans, quat)
            except TransformError as exc:
                raise RecordingError(f"{rec.path}: pose topic {topic}: the pose at stamp "
                                     f"{message_stamp_ns(msg, log_ns)} ns is refused "
                                     f"({exc.detail.split(': ', 1)[-1]})") from None
        if self.frame is None:
            raise RecordingError(f"{rec.path}: pose topic {topic} has no messages" if not info.count else
                                 f"{rec.path}: pose topic {topic} lists {info.count} messages but none of a pose "
                                 f"type could be read")
        self.tolerance_ns = tolerance_ns

    def pose(self, stamp_ns: int) -> np.ndarray:
        return self.tf.lookup(self.frame, "__camera__", stamp_ns, tolerance_ns=self.tolerance_ns)

    def gap_warnings(self) -> list[str]:
        """The TF buffer's warnings for lookups interpolated across a long gap, naming the topic."""
        link = f"TF link {self.frame} -> __camera__"
        return [w.replace(link, f"{self.rec_path}: pose topic {self.topic}") for w in self.tf.gap_warnings()]


def iter_frames(rec, roles: Roles | None = None, pose_source: str = "tf", pose_topic: str | None = None,
                tolerance_s: float = 0.05, start_s: float | None = None, end_s: float | None = None,
                every: int = 1, stats: FrameStats | None = None, tf: TfBuffer | None = None,
                require_color: bool = False) -> Iterator[RGBDFrame]:
    """Yield RGBDFrames of a Recording.

    pose_source: "tf" (world_frame <- camera_frame from /tf, /tf_static), "topic" (a pose topic giving
    T_world_camera, `pose_topic`), or "none". start_s/end_s: seconds from the start of the recording.
    every: keep every n-th depth frame. tolerance_s: largest |t_colour - t_depth| for a pair, and how far
    a pose may be extrapolated beyond the TF / pose range. Frames without colour are kept (color=None)
    unless require_color. `stats` (a FrameStats) is filled in while streaming. Every argument is checked
    when the first frame is asked for, before any image is decoded.
    """
    if pose_source not in POSE_SOURCES:
        raise ConfigError(f"expected one of {', '.join(POSE_SOURCES)}, got {pose_source!r}", parameter="pose_source")
    if every < 1:
        raise ConfigError(f"expected an integer >= 1, got {every}", parameter="every")
    tolerance_s = check_seconds(tolerance_s, "tolerance_s", minimum=0.0)
    start_s, end_s = check_window(start_s, end_s)
    stats = stats if stats is not None else FrameStats()
    if roles is None:
        if tf is None and pose_source == "tf":
            tf = TfBuffer.from_recording(rec)
        roles = detect_roles(rec, tf=tf)
    depth_topic = _require_topics(rec, roles)
    stats.notes += [n for n in roles.notes if n not in stats.notes]  # which of several topics was taken
    tol_ns = int(round(tolerance_s * 1e9))
    stats.tolerance_ns = tol_ns
    cloud = POINTCLOUD2 in rec.topics[depth_topic].msgtypes
    reduction = ""
    if cloud:
        K, width, height, lens, _ = _cloud_camera(rec, roles, depth_topic, stats)
    else:
        K, width, height, lens, reduction = _depth_camera(rec, roles, depth_topic, stats.notes)
    sdk = is_sdk_stream(rec, depth_topic)  # a RealSense SDK recording: depth units, colour through its extrinsics
    if pose_source == "tf" and sdk and not roles.camera_frame:
        raise RecordingError(f"{rec.path}: a RealSense SDK recording has no TF camera poses (its depth frames name "
                             f"no TF frame); take no poses (pose source 'none') or track them (ICP)",
                             parameter="pose_source")
    if pose_source == "tf":
        tf = tf if tf is not None else TfBuffer.from_recording(rec)
        pose_fn, gap_warnings = _tf_poses(rec, roles, depth_topic, tf, tol_ns, stats), tf.gap_warnings
    elif pose_source == "topic":
        pose_fn, gap_warnings = _topic_poses(rec, pose_topic, tol_ns, stats)
    else:
        pose_fn, gap_warnings = None, None
    start_ns, end_ns = _time_window(rec, start_s, end_s)
    reg = color_info_topic = None
    if sdk:
        stats.depth_units, _, note = depth_units(rec, depth_topic)
        stats.notes += [note] if note else []
    if roles.color_topic is not None:
        if sdk and is_sdk_stream(rec, roles.color_topic):
            reg = sdk_color_registration(rec, depth_topic, roles.color_topic)
        else:
            reg = color_registration(rec, depth_topic, roles.color_topic, roles.info_topic, tf)
            color_info_topic = reg.info_topic if reg.mode == "project" else None  # followed as it changes
        reg = check_color_size(reg, rec, roles.color_topic, None if cloud else (width, height))
        stats.color_registration = reg.as_dict()
        if reg.mode == "none":  # colour that cannot be placed is left out, not painted beside its surface
            roles = replace(roles, color_topic=None)
    if cloud:  # the cloud's own camera, fixed: later camera infos are not read
        roles = replace(roles, info_topic=None)
    pairer = FramePairer(rec, roles, depth_topic, K, width, height, pose_fn, tol_ns, stats, require_color, reg,
                          lens, cloud, stats.depth_units, reduction, color_info_topic)
    yield from pairer.stream(start_ns, end_ns, every)
    if gap_warnings is not None:  # poses interpolated across a long gap of a TF link or the pose topic: known once
        stats.notes += [w for w in gap_warnings() if w not in stats.notes]  # the frames are read


def check_seconds(value: float, parameter: str, minimum: float = -MAX_SECONDS) -> float:
    """`value` as a float in [minimum, MAX_SECONDS] seconds; ConfigError naming `parameter` otherwise (NaN, inf,
    or so large that it overflows nanosecond stamps)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"expected a number of seconds, got {value!r}", parameter=parameter) from None
    if not (minimum <= v <= MAX_SECONDS):
        raise ConfigError(f"expected a finite number of seconds in [{minimum:g}, {MAX_SECONDS:g}], got {value}",
                          parameter=parameter)
    return v


def _depth_camera(rec, roles: Roles, depth_topic: str,
                  notes: list[str]) -> tuple[np.ndarray, int, int, Undistorter, str]:
    """(K, width, height, lens, reduction) of the depth camera: its first camera info's (io.camera_info.image_camera:
    roi, binning, P for a rectified topic), or the given intrinsics (the size of the first depth image; no
    distortion); a camera info in another frame than the depth images, or P taken for K, is said in notes."""
    if roles.intrinsics is not None:
        K = intrinsics_matrix(*roles.intrinsics)
        first = rec.first_message(depth_topic)
        h, w = decode_depth(first, f"{rec.path}: {depth_topic}").shape if first is not None else (0, 0)
        if (problem := field_of_view_problem(K, w, h)) is not None:
            raise ConfigError(f"{rec.path}: {depth_topic}: {problem}", parameter="intrinsics")
        return K, w, h, Undistorter.pinhole(K), ""
    first_info = rec.first_message(roles.info_topic)
    if first_info is None:
        count = rec.topics[roles.info_topic].count
        raise RecordingError(f"{rec.path}: camera info topic {roles.info_topic} has no messages" if not count else
                             f"{rec.path}: camera info topic {roles.info_topic} lists {count} messages but none "
                             f"could be read")
    cam = image_camera(first_info, f"{rec.path}: {roles.info_topic}", depth_topic)
    K, width, height = cam.K, cam.width, cam.height
    notes += [n for n in cam.notes if n not in notes]
    first = rec.first_message(depth_topic)
    info_frame, depth_frame = (header_frame(m).lstrip("/") if m is not None else "" for m in (first_info, first))
    if info_frame and depth_frame and info_frame != depth_frame:  # no info in the depth frame: roles took this one
        notes.append(f"camera info {roles.info_topic} is in frame {info_frame!r}, the depth images in "
                     f"{depth_frame!r}: its intrinsics (fx={K[0, 0]:.4g}) may be another camera's (give the "
                     f"depth camera's intrinsics if they are)")
    return K, width, height, Undistorter(K, cam.model, cam.D), cam.reduction


def _cloud_camera(rec, roles: Roles, topic: str, stats: FrameStats
                  ) -> tuple[np.ndarray, int, int, Undistorter, str]:
    """(K, width, height, pinhole lens, where K comes from) of an organized cloud's camera: the given intrinsics;
    else its camera info's K (scaled to the cloud's size) when the cloud's points project onto their pixels with
    it; else K recovered from the first cloud (io.pointcloud2.fit_intrinsics), said in stats.notes. No lens
    distortion: the points are already in space."""
    first = rec.first_message(topic)
    where = f"{rec.path}: depth topic {topic}"
    h, w = int(first.height), int(first.width)
    if roles.intrinsics is not None:  # the user's word, but a K that misses the points unprojects them elsewhere
        K = intrinsics_matrix(*roles.intrinsics)
        if (problem := field_of_view_problem(K, w, h)) is not None:
            raise ConfigError(f"{where}: {problem}", parameter="intrinsics")
        if (rms := pinhole_rms(first, K, where)) > MAX_PINHOLE_RMS_PX:
            stats.notes.append(f"depth from the organized point cloud {topic} ({w}x{h}): the given intrinsics miss "
                               f"its points by {rms:.3g} px RMS (the cloud's own camera puts each point on its "
                               f"pixel); its depth is unprojected with them all the same")
        return K, w, h, Undistorter.pinhole(K), "given"
    disagree = ""
    info = rec.first_message(roles.info_topic) if roles.info_topic is not None else None
    if info is not None:
        K, iw, ih, *_ = image_camera(info, f"{rec.path}: {roles.info_topic}")
        if (iw, ih) != (w, h) and iw and ih:
            K = scaled_intrinsics(K, (w / iw, h / ih))
        rms = pinhole_rms(first, K, where)
        if rms <= MAX_PINHOLE_RMS_PX:
            return K, w, h, Undistorter.pinhole(K), f"camera info {roles.info_topic}"
        disagree = f"camera info {roles.info_topic} misses its points by {rms:.3g} px RMS, so "
    (fx, fy, cx, cy), rms = fit_intrinsics(first, where)
    stats.notes.append(f"depth from the organized point cloud {topic} ({w}x{h}): {disagree}its intrinsics were "
                       f"recovered from the cloud: fx={fx:.2f} fy={fy:.2f} cx={cx:.2f} cy={cy:.2f} "
                       f"({rms:.2g} px RMS)")
    K = intrinsics_matrix(fx, fy, cx, cy)
    return K, w, h, Undistorter.pinhole(K), "recovered from the cloud"


def cloud_depth_source(rec, roles: Roles) -> dict | None:
    """What an organized-cloud depth topic gives (for a summary): size, whether it carries colour, and the
    intrinsics that reading its frames will use and where they come from; `problem` instead when they cannot be
    had. None when the depth topic is no PointCloud2 topic (or, without a depth topic, no cloud is there)."""
    topic = roles.depth_topic
    if topic is None:  # no depth topic: say why a cloud that is there is none
        clouds = unorganized_clouds(rec)
        return {"topic": clouds[0][0], "problem": f"not a depth source: it {clouds[0][1]}"} if clouds else None
    if topic not in rec.topics or POINTCLOUD2 not in rec.topics[topic].msgtypes:
        return None
    first = rec.first_message(topic)
    if first is None or not is_cloud(first):
        return {"topic": topic, "problem": "no readable message"}
    out = {"topic": topic, "width": int(first.width), "height": int(first.height),
           "color": "rgb field" if has_color(first) and roles.color_topic is None else roles.color_topic}
    stats = FrameStats()
    try:
        _require_topics(rec, roles)
        K, _, _, _, source = _cloud_camera(rec, roles, topic, stats)
    except RecordingError as exc:
        return {**out, "problem": str(exc)}
    return {**out, "intrinsics": {"fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]),
                                  "cy": float(K[1, 2])}, "intrinsics_source": source, "notes": stats.notes}


def _require_topics(rec, roles: Roles) -> str:
    """The depth topic; RecordingError unless the depth, camera info (but for a cloud) and (when set) colour
    topics are there, and a depth cloud is organized."""
    depth_topic = roles.depth_topic
    if depth_topic is None:
        cut = rec.cut_note() if hasattr(rec, "cut_note") else ""  # a truncated file: it may be in the lost part
        clouds = unorganized_clouds(rec)
        if clouds:
            name, why = clouds[0]
            raise RecordingError(f"{rec.path}: no depth image topic found{cut}, and point cloud {name} {why}",
                                 parameter="depth_topic")
        avail = ", ".join(f"{n} ({i.msgtype})" for n, i in rec.topics.items()) or "none"
        raise RecordingError(f"{rec.path}: no depth image topic found{cut}; topics: {avail}",
                             parameter="depth_topic")
    info = require_role_topic(rec, depth_topic, "depth topic")
    if POINTCLOUD2 in info.msgtypes:
        first = rec.first_message(depth_topic)
        why = (organized_problem(first) if first is not None and is_cloud(first) else
               f"has no readable message (of {info.count})")
        if why:
            raise RecordingError(f"{rec.path}: depth topic {depth_topic}: point cloud {why}", parameter="depth_topic")
    elif roles.info_topic is None and roles.intrinsics is None:
        raise RecordingError(f"{rec.path}: no sensor_msgs/CameraInfo topic for depth topic {depth_topic} "
                             f"(give the intrinsics fx,fy,cx,cy)", parameter="intrinsics")
    if roles.info_topic is not None:
        require_role_topic(rec, roles.info_topic, "camera info topic")
    if roles.color_topic is not None:
        require_role_topic(rec, roles.color_topic, "colour topic")
    return depth_topic




def _tf_poses(rec, roles: Roles, depth_topic: str, tf: TfBuffer | None, tol_ns: int,
              stats: FrameStats) -> PoseLookup:
    """Camera pose at a stamp from TF (world frame <- camera frame); None (counted) outside the TF range.
    The chain of links is checked now, so a missing link fails before any frame, naming both frames."""
    tf = tf if tf is not None else TfBuffer.from_recording(rec)
    camera = roles.camera_frame
    if camera is None:
        first_depth = rec.first_message(depth_topic)
        camera = header_frame(first_depth).lstrip("/") if first_depth is not None else ""
    if not camera:
        raise RecordingError(f"{rec.path}: depth topic {depth_topic} has no header frame_id",
                             parameter="camera_frame")
    world = roles.world_frame
    if world is None:
        raise TransformError(f"{rec.path}: no TF world frame found for camera frame {camera!r} "
                             f"(no /tf data?); name the world frame, or take no poses (pose source "
                             f"'none')", parameter="world_frame")
    try:
        tf.require_chain(world, camera)
    except TransformError as exc:
        raise TransformError(f"{rec.path}: {exc}", parameter="camera_frame/world_frame") from None

    span = tf.dynamic_span()

    def pose(stamp_ns: int) -> np.ndarray | None:
        try:
            return tf.lookup(world, camera, stamp_ns, tolerance_ns=tol_ns)
        except TransformError:
            inside = span is not None and span[0] <= stamp_ns <= span[1]
            stats.drop(DROP_CHAIN_BROKEN if inside else DROP_NO_POSE)
            return None

    return pose


def _topic_poses(rec, pose_topic: str | None, tol_ns: int,
                 stats: FrameStats) -> tuple[PoseLookup, Callable[[], list[str]]]:
    """Camera pose at a stamp from a pose topic, interpolated, None (counted) beyond its messages; and the gap
    warnings of the lookups made so far."""
    if pose_topic is None:
        raise ConfigError("needed with pose source 'topic' (a PoseStamped/Odometry/... topic)",
                          parameter="pose_topic")
    path = _PosePath(rec, pose_topic, tol_ns)

    def pose(stamp_ns: int) -> np.ndarray | None:
        try:
            return path.pose(stamp_ns)
        except TransformError:
            stats.drop(DROP_NO_POSE_TOPIC)
            return None

    return pose, path.gap_warnings


def window_depth_count(rec, depth_topic: str, start_s: float | None = None, end_s: float | None = None,
                       tolerance_s: float = 0.05) -> int:
    """The most depth messages iter_frames can select with this time window: those it reads (the window widened
    by the tolerance), counted without decoding them."""
    start_s, end_s = check_window(start_s, end_s)
    start_ns, end_ns = _time_window(rec, start_s, end_s)
    tol_ns = int(round(check_seconds(tolerance_s, "tolerance_s", minimum=0.0) * 1e9))
    return rec.count_messages(depth_topic, None if start_ns is None else max(0, start_ns - tol_ns),
                              None if end_ns is None else end_ns + tol_ns)


def _time_window(rec, start_s: float | None, end_s: float | None) -> tuple[int | None, int | None]:
    """[start, end] in log nanoseconds from seconds after the recording's first message (None: open)."""
    t0 = rec.start_ns or 0
    start_ns = None if start_s is None else t0 + int(start_s * 1e9)
    end_ns = None if end_s is None else t0 + int(end_s * 1e9)
    t1 = getattr(rec, "end_ns", None)  # a window outside the recording selects nothing: said, not "no frames"
    if start_ns is not None and t1 is not None and start_ns > t1:
        raise ConfigError(f"start {start_s:g} s is after the recording's end (it lasts {(t1 - t0) * 1e-9:.3f} s; "
                          f"seconds count from its first message)", parameter="start_s")
    return start_ns, end_ns


def check_window(start_s: float | None, end_s: float | None) -> tuple[float | None, float | None]:
    """(start_s, end_s) checked without the recording (None: open): finite seconds, start <= end, end >= 0 (the
    seconds count from the recording's first message: a negative end selects nothing); ConfigError naming the
    parameter (kinfu batch checks a plan's window with it before any work)."""
    start_s = None if start_s is None else check_seconds(start_s, "start_s")
    end_s = None if end_s is None else check_seconds(end_s, "end_s")
    if start_s is not None and end_s is not None and end_s < start_s:
        raise ConfigError(f"start {start_s} s is after end {end_s} s", parameter="start_s/end_s")
    if end_s is not None and end_s < 0:
        raise ConfigError(f"end {end_s:g} s is before the recording's start (seconds count from its first "
                          f"message)", parameter="end_s")
    return start_s, end_s
