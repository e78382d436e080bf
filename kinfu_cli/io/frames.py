"""Frame assembly: depth images paired with the nearest colour image and the camera pose at the depth stamp.

`iter_frames` streams the depth, colour and camera-info topics once, in log order, keeping only the messages
that may still be a partner (about a second of them), so memory does not grow with the recording. Partners are
matched by stamp, not by log order: a depth image takes the camera info of its own stamp (image_transport logs it
after the image) and the nearest colour image, whichever is logged first. Stamps are the header stamps of the
images (the log time where a header stamp is zero). Frames that cannot be used are counted
by reason in a `FrameStats`, which the fusion report prints.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from kinfu_cli.core.camera import field_of_view_problem, intrinsics_matrix, scaled_intrinsics
from kinfu_cli.core.errors import ConfigError, RecordingError, TransformError
from kinfu_cli.io.camera_info import image_camera, is_rectified_topic
from kinfu_cli.io.color_registration import (ColorRegistration, ColorSizeError, check_color_size, color_registration,
                                             color_size_reason, colour_camera_of, register_color)
from kinfu_cli.io.messages import (POSE_TYPES, decode_color, decode_depth, header_frame, header_stamp_ns,
                                   normalize_msgtype, pose_message_to_tq)
from kinfu_cli.io.pointcloud2 import (MAX_PINHOLE_RMS_PX, POINTCLOUD2, decode_cloud, fit_intrinsics, has_color,
                                      is_cloud, organized_problem, pinhole_rms)
from kinfu_cli.io.realsense_bag import depth_units, is_sdk_stream, sdk_color_registration
from kinfu_cli.io.roles import Roles, detect_roles, require_role_topic, unorganized_clouds
from kinfu_cli.io.tf_buffer import TfBuffer
from kinfu_cli.io.undistort import Undistorter, reproject_pinhole

POSE_SOURCES = ("tf", "topic", "none")
MAX_SECONDS = 1e7  # bound of times and tolerances (116 days): stamps in ns stay far inside int64

DROP_NO_POSE = "no camera pose within the TF range"
DROP_CHAIN_BROKEN = "no TF chain to the camera at that time"  # inside the TF's time, no chain with transforms there
DROP_NO_POSE_TOPIC = "no pose message within tolerance"
DROP_EMPTY = "depth image has no valid pixel"
DROP_NO_PIXELS = "depth image is empty (0 pixels wide or high)"
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
    color_mask: np.ndarray | None = None  # bool (H, W): False where colour has no sample (projected colour)


# the share of a run's frames that may lack a colour image within the tolerance before a warning (the first and
# last frames often do: the colour stream starts and stops at other times)
UNPAIRED_COLOR_WARN = 0.10
# how long (log time) colour images are kept for depth messages still to come: a depth driver's processing and
# the recorder's queue log depth images after the colour images of the same instant (some 30-300 ms)
COLOR_LOOKAHEAD_NS = 1_000_000_000
MAX_16BIT_MM = 65535  # the largest depth a 16-bit millimetre image holds (65535 itself reads as no measurement)


@dataclass
class FrameStats:
    """How many depth frames were used, skipped (every n-th, time window) and dropped (reason -> count)."""

    depth_messages: int = 0
    used: int = 0
    skipped: int = 0
    without_color: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    color_registration: dict | None = None  # ColorRegistration.as_dict() when there is a colour topic
    notes: list[str] = field(default_factory=list)  # what was assumed to read the frames (a warning each)
    depth_units: float | None = None  # m per unit of 16-bit depth when not mm (a RealSense SDK recording's)
    # frames used without colour although the colour topic could be placed: no colour image within the tolerance;
    # the nearest one's distance in time (None when there was none at all) and the tolerance
    color_unpaired: int = 0
    color_nearest_ns: int | None = None
    tolerance_ns: int = 0
    # depth images whose stamp is equal to or earlier than the one before (kept: said in a warning); the first one
    stamps_not_increasing: int = 0
    first_not_increasing_ns: int | None = None
    # 32FC1 depth pixels beyond what a 16-bit millimetre image holds (65.535 m: millimetres stored as metres?)
    pixels_over_16bit_mm: int = 0
    frames_over_16bit_mm: int = 0
    # depth frames logged so long after their stamp that colour images near it were no longer kept
    color_cut_short: int = 0
    # colour images whose stamp is earlier than the one before (a colour clock that went back); the first one, how
    # far back it went, and the colour topic
    color_stamps_backwards: int = 0
    first_color_backwards_ns: int | None = None
    color_backwards_ns: int = 0
    color_topic: str | None = None
    # colour images paired with a depth frame that hold no pixel (0 wide or high): the frame goes without colour
    color_empty: int = 0

    def drop(self, reason: str) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def warnings(self, recording: str) -> list[str]:
        """What reading the frames assumed (notes), and why frames of a recording with a colour topic carry no
        colour (io.color_registration could not place it): one warning each, for every command that reads
        frames."""
        out = [f"{recording}: {n}" for n in self.notes]
        reg = self.color_registration
        if reg and reg["mode"] == "none":
            out.append(f"{recording}: frames without colour: {reg['reason']}, so the colour images cannot be placed "
                       f"on the depth (resizing them would paint each surface with its neighbour's)")
        if self.color_stamps_backwards:
            out.append(f"{recording}: {self.color_stamps_backwards} colour images on {self.color_topic} have a stamp "
                       f"earlier than the one before (the first at {self.first_color_backwards_ns} ns, "
                       f"{self.color_backwards_ns / 1e6:.0f} ms back): the colour clock went back (a driver "
                       f"restart?); a depth frame takes colour only from the images before such a step back, or, when "
                       f"its own stamps went back too, after it, so frames may be left without colour")
        if self.color_unpaired > UNPAIRED_COLOR_WARN * max(self.used, 1):  # a few at the ends are usual
            near = ("no colour image at all in the frames' time window" if self.color_nearest_ns is None else
                    f"the nearest colour image {self.color_nearest_ns / 1e6:.0f} ms from a depth frame, over "
                    f"the {self.tolerance_ns / 1e6:.0f} ms tolerance")
            why = ("the colour stamps went back: see the warning before" if self.color_stamps_backwards else
                   "a larger tolerance pairs images further apart in time")
            out.append(f"{recording}: {self.color_unpaired} of {self.used} frames have no colour ({near}); their "
                       f"surfaces stay uncoloured ({why})")
        if self.color_cut_short:
            out.append(f"{recording}: {self.color_cut_short} depth frames were logged more than "
                       f"{COLOR_LOOKAHEAD_NS / 1e9:g} s after colour images within the tolerance of their stamp, "
                       f"which were no longer kept: these frames may carry a colour image farther in time than the "
                       f"nearest, or none")
        if self.color_empty:
            out.append(f"{recording}: {self.color_empty} colour images on {self.color_topic} paired with depth frames "
                       f"are empty (0 pixels wide or high: a driver fault?); those frames carry no colour")
        if self.dropped.get(DROP_NO_PIXELS):
            out.append(f"{recording}: {self.dropped[DROP_NO_PIXELS]} of {self.depth_messages} depth images are empty "
                       f"(0 pixels wide or high: a driver fault?); they were left out")
        if self.stamps_not_increasing:
            out.append(f"{recording}: {self.stamps_not_increasing} of {self.depth_messages} depth images have a "
                       f"stamp equal to or earlier than the one before (the first at {self.first_not_increasing_ns} "
                       f"ns): repeated or backward stamps (a driver or clock fault?); they are used at the stamps "
                       f"they carry")
        if self.pixels_over_16bit_mm:
            out.append(f"{recording}: {self.pixels_over_16bit_mm} depth pixels in {self.frames_over_16bit_mm} "
                       f"frames read {MAX_16BIT_MM / 1000:g} m or more (32FC1 depth is in metres: millimetres "
                       f"stored as metres?); a 16-bit millimetre depth image (kinfu export) cannot hold them and "
                       f"writes them as no measurement (65535)")
        return out

    def as_dict(self) -> dict:
        return {"depth_messages": self.depth_messages, "used": self.used, "skipped": self.skipped,
                "without_color": self.without_color, "dropped": dict(self.dropped),
                "dropped_total": self.dropped_total,
                **({"color_registration": self.color_registration} if self.color_registration else {}),
                **({"notes": list(self.notes)} if self.notes else {}),
                **({"depth_units_m": self.depth_units} if self.depth_units is not None else {}),
                **({"stamps_not_increasing": self.stamps_not_increasing} if self.stamps_not_increasing else {}),
                **({"color_cut_short": self.color_cut_short} if self.color_cut_short else {}),
                **({"color_stamps_backwards": self.color_stamps_backwards} if self.color_stamps_backwards else {}),
                **({"pixels_over_16bit_mm": self.pixels_over_16bit_mm} if self.pixels_over_16bit_mm else {}),
                **({"color_empty": self.color_empty} if self.color_empty else {})}


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
                                     f"{frame!r} at stamp {_stamp(msg, log_ns)} ns; expected one frame")
            try:  # the checks of a TF transform: finite, unit quaternion, within reach
                self.tf.add_quat(self.frame, "__camera__", _stamp(msg, log_ns), trans, quat)
            except TransformError as exc:
                raise RecordingError(f"{rec.path}: pose topic {topic}: the pose at stamp {_stamp(msg, log_ns)} ns is "
                                     f"refused ({exc.detail.split(': ', 1)[-1]})") from None
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
    pairer = _FramePairer(rec, roles, depth_topic, K, width, height, pose_fn, tol_ns, stats, require_color, reg,
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


PoseLookup = Callable[[int], "np.ndarray | None"]


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


@dataclass(frozen=True)
class _Camera:
    """A depth camera as one camera info gives it: intrinsics, image size, roi / binning note, lens; and, for a
    rectified colour topic in its frame, the pinhole camera (P) its colour images are already on."""

    K: np.ndarray
    width: int
    height: int
    reduction: str
    lens: Undistorter
    color_K: np.ndarray | None = None


@dataclass
class _Waiting:
    """A depth message waiting for its colour partner and for the camera info of its stamp."""

    index: int
    stamp: int
    msg: object
    cam: _Camera  # the camera info of its stamp, or (until that comes) the latest one read before it
    info_until: int | None  # log ns until which the camera info of its stamp may come; None: `cam` is settled
    color_pass: int  # which run of the colour stream's increasing stamps it may take colour from


class _FramePairer:
    """Streams the depth, colour and camera-info topics once, in log order, pairing each depth image by stamp with
    the nearest colour image within the tolerance, the camera info of its stamp and its camera pose. Only the
    messages still waiting for a partner are kept: depth frames until no closer colour image can arrive and their
    camera info came (or cannot come), colour images (undecoded) for COLOR_LOOKAHEAD_NS of log time (depth is often
    logged later than the colour of the same instant, and not always in stamp order) or while a waiting frame can
    use them, camera infos for COLOR_LOOKAHEAD_NS; frames that lost a partner to that bound are counted
    (color_cut_short). Colour stamps that go back (a driver restart) start a new pass of colour images: a depth
    frame takes colour of the pass of its time only (its stamps go back too to reach the new one)."""

    def __init__(self, rec, roles: Roles, depth_topic: str, K: np.ndarray, width: int, height: int,
                 pose_fn: PoseLookup | None, tol_ns: int, stats: FrameStats, require_color: bool,
                 registration: ColorRegistration | None = None, lens: Undistorter | None = None,
                 cloud: bool = False, depth_units: float | None = None, reduction: str = "",
                 color_info_topic: str | None = None) -> None:
        self.rec = rec
        # 16-bit depth in these units (m) instead of mm: a factor on decode_depth's mm reading
        self.unit_factor = None if depth_units is None else np.float32(depth_units / 0.001)
        self.cloud = cloud  # depth (and colour, with an rgb field) from an organized PointCloud2
        self.registration = registration
        self.depth_topic = depth_topic
        self.info_topic = roles.info_topic
        self.color_topic = roles.color_topic
        # the projected colour camera's info topic: the registration takes each one's camera (not the SDK's)
        self.color_info_topic = color_info_topic if color_info_topic != self.info_topic else None
        # (stamp, log ns, registration with its camera) of the colour camera infos read within the look-ahead
        self.color_infos: deque[tuple[int, int, ColorRegistration]] = deque()
        # the latest camera info read (the first one's, with its lens, until the stream reads one): K, size, roi /
        # binning of the calibrated sensor ("" when none: image_camera)
        first_info = rec.first_message(self.info_topic) if self._rectified_color() else None
        self.camera = _Camera(K, width, height, reduction, lens if lens is not None else Undistorter.pinhole(K),
                              None if first_info is None else self._color_K(first_info))
        self.infos: deque[tuple[int, int, _Camera]] = deque()  # (stamp, log ns, camera) read within the look-ahead
        self.pose_fn = pose_fn
        self.tol_ns = tol_ns
        self.stats = stats
        self.require_color = require_color
        self.pending: deque[_Waiting] = deque()
        # (stamp, log ns, colour msg, pass, the registration when it was read), decoded when paired
        self.colors: deque[tuple[int, int, object, int, ColorRegistration | None]] = deque()
        self.depth_stamp: int | None = None  # of the latest depth message read: later ones should not be earlier
        self.color_stamp: int | None = None  # of the latest colour message read
        self.color_pass = 0  # colour stamps that went back by more than the tolerance so far
        self.depth_pass = 0  # the colour pass the depth messages read now take colour from
        self.depth_back: tuple[int, int] | None = None  # (log ns, index) of the latest depth stamp that went back
        # stamps of the colour images dropped by the look-ahead, as [first, last] runs without a gap over twice the
        # tolerance: a depth stamp within the tolerance of a run had a colour image that near
        self.dropped_colors: deque[list[int]] = deque()

    def stream(self, start_ns: int | None, end_ns: int | None, every: int) -> Iterator[RGBDFrame]:
        """Frames of depth messages recorded (log time) in [start_ns, end_ns] (either None: open), every n-th;
        messages within the tolerance outside the window are read too, as partners."""
        tol_ns, stats, pending = self.tol_ns, self.stats, self.pending
        read_start = None if start_ns is None else max(0, start_ns - tol_ns)
        # colour and camera infos logged up to the look-ahead earlier may be the partners of a depth message
        look_start = None if start_ns is None else max(0, start_ns - tol_ns - COLOR_LOOKAHEAD_NS)
        read_end = None if end_ns is None else end_ns + tol_ns
        # and those logged up to the look-ahead later may be the partners of the last depth messages
        look_end = None if end_ns is None else read_end + COLOR_LOOKAHEAD_NS
        partners = [t for t in (self.info_topic, self.color_topic, self.color_info_topic) if t]
        index = 0  # position of the depth message on its topic among those read
        kept = 0  # depth messages inside the window so far
        last_stamp = None  # of the previous depth message inside the window
        for topic, log_ns, msg in self.rec.messages([self.depth_topic] + partners,
                                                    start_ns=look_start if partners else read_start,
                                                    end_ns=look_end if partners else read_end):
            if pending and pending[0].info_until is not None and pending[0].info_until < log_ns:
                self._settle(lambda w: w.info_until < log_ns)  # no camera info of their stamps came in time
                yield from self._flush_ready()
            if read_end is not None and log_ns > read_end:  # read for the partners' look-ahead only
                if not pending:
                    break  # no frame waits for a partner
                if topic == self.depth_topic:
                    continue  # depth after the window is not the window's
            if topic == self.info_topic:
                self._read_info(msg, log_ns)
                yield from self._flush_ready()
                continue
            if topic == self.color_info_topic:
                self._read_color_info(msg, log_ns)
                continue
            stamp = _stamp(msg, log_ns)
            if topic == self.color_topic:
                self._read_color(stamp, log_ns, msg)
                yield from self._flush(stamp)
                self._forget_colors(log_ns)
                continue
            if read_start is not None and log_ns < read_start:
                continue  # before the tolerance margin: read for the partners' look-ahead only
            # a depth message: the window is in the recording's time (log time, as `rosbag play --start` and the
            # recording's start use), not the header's, whose clock may be another (a device's, simulated time)
            index += 1
            if self.depth_stamp is not None and stamp < self.depth_stamp:
                self.depth_pass = self.color_pass  # its clock went back too: the colour's latest pass is its own
                self.depth_back = (log_ns, index - 1)
            self.depth_stamp = stamp
            if (start_ns is not None and log_ns < start_ns) or (end_ns is not None and log_ns > end_ns):
                continue  # read only for the tolerance margin of the time window
            stats.depth_messages += 1
            if last_stamp is not None and stamp <= last_stamp:
                stats.stamps_not_increasing += 1
                if stats.first_not_increasing_ns is None:
                    stats.first_not_increasing_ns = stamp
            last_stamp = stamp
            kept += 1
            if (kept - 1) % every:
                stats.skipped += 1
                continue
            cam = self._info_of(stamp)  # the camera info of its stamp when it came first; else it may come next
            pending.append(_Waiting(index - 1, stamp, msg, cam or self.camera,
                                    None if cam is not None or self.info_topic is None else log_ns + COLOR_LOOKAHEAD_NS,
                                    self.depth_pass))
            if self.color_topic is None:
                yield from self._flush(None)
            elif len(pending) > 64:  # colour stream stalled: do not hold depth frames forever
                frame = self._emit(pending.popleft())
                if frame is not None:
                    yield frame
        yield from self._flush(None, settled_only=False)

    def _rectified_color(self) -> bool:
        """Whether colour images are the depth camera's own pixels on a rectified topic (already undistorted onto
        the camera info's P: not to be undistorted again)."""
        return bool(self.info_topic) and self.registration_mode() == "same-frame" and is_rectified_topic(
            self.color_topic)

    def _color_K(self, msg: object) -> np.ndarray | None:
        """The pinhole camera of a rectified colour topic by camera info `msg` (P, its roi and binning); None when
        its P cannot be read (the colour is then taken as on K)."""
        try:
            return image_camera(msg, f"{self.rec.path}: {self.info_topic}", self.color_topic).K
        except RecordingError:
            return None

    def _read_info(self, msg: object, log_ns: int) -> None:
        """Take a camera info: the latest one from now, and the one of the waiting frames of its stamp; the frames
        before its stamp keep theirs (no info of their own stamp comes after a later one)."""
        info = image_camera(msg, f"{self.rec.path}: {self.info_topic}", self.depth_topic)
        lens = self.camera.lens
        if not (lens.model == info.model and np.array_equal(lens.D, info.D) and np.array_equal(lens.K, info.K)):
            lens = Undistorter(info.K, info.model, info.D)
        self.camera = _Camera(info.K, info.width, info.height, info.reduction, lens,
                              self._color_K(msg) if self._rectified_color() else None)
        stamp = _stamp(msg, log_ns)
        self.infos.append((stamp, log_ns, self.camera))
        while self.infos[0][1] < log_ns - COLOR_LOOKAHEAD_NS:
            self.infos.popleft()
        for w in self.pending:
            if w.info_until is not None and w.stamp == stamp:
                w.cam = self.camera
        self._settle(lambda w: w.stamp <= stamp)

    def _info_of(self, stamp: int) -> _Camera | None:
        """The camera of the latest camera info read with this stamp (None when none is kept)."""
        return next((cam for s, _, cam in reversed(self.infos) if s == stamp), None)

    def _settle(self, done: Callable[[_Waiting], bool]) -> None:
        """Waiting frames for which `done` says their camera info is the one they hold."""
        for w in self.pending:
            if w.info_until is not None and done(w):
                w.info_until = None

    def _read_color(self, stamp: int, log_ns: int, msg: object) -> None:
        """Keep a colour image; a stamp before the one before is counted, and when it goes back by more than the
        tolerance a new pass of colour images begins (the waiting frames are of the one before)."""
        stats = self.stats
        if self.color_stamp is not None and stamp < self.color_stamp:
            stats.color_stamps_backwards += 1
            if stats.first_color_backwards_ns is None:
                stats.first_color_backwards_ns, stats.color_backwards_ns = stamp, self.color_stamp - stamp
                stats.color_topic = self.color_topic
            if self.color_stamp - stamp > self.tol_ns:
                self.color_pass += 1
                self.dropped_colors.clear()  # stamps of the other clock: no frame of this pass lost them
                if self.depth_back is not None and self.depth_back[0] >= log_ns - COLOR_LOOKAHEAD_NS:
                    self.depth_pass = self.color_pass  # the depth clock went back just before: the same restart
                    for w in self.pending:
                        if w.index >= self.depth_back[1]:
                            w.color_pass = self.color_pass
        self.color_stamp = stamp
        self.colors.append((stamp, log_ns, msg, self.color_pass, self.registration))

    def _read_color_info(self, msg: object, log_ns: int) -> None:
        """Take a colour camera info: the colour images of its stamp, and those after it, are projected with its
        camera (a re-calibration or a resolution change mid-stream); one that cannot be read is said, and the one
        before it kept."""
        if self.registration is None or self.registration.mode != "project":
            return
        where = f"{self.rec.path}: {self.color_info_topic}"
        try:
            lens, size = colour_camera_of(msg, where, image_topic=self.color_topic)
        except RecordingError as exc:
            note = f"{exc}; the colour images of its time are projected with the camera info before it"
            self.stats.notes += [note] if note not in self.stats.notes else []
            return
        reg = self.registration
        if not (size == reg.color_size and lens.model == reg.lens.model and np.array_equal(lens.K, reg.lens.K)
                and np.array_equal(lens.D, reg.lens.D)):
            self.registration = replace(reg, lens=lens, color_size=size)
        self.color_infos.append((_stamp(msg, log_ns), log_ns, self.registration))
        while self.color_infos[0][1] < log_ns - COLOR_LOOKAHEAD_NS:
            self.color_infos.popleft()

    def _color_camera(self, stamp: int, read_with: ColorRegistration) -> ColorRegistration:
        """The registration of the colour image of `stamp`: with the colour camera info of its stamp when one is
        kept, else `read_with` (the one when the image was read)."""
        return next((reg for s, _, reg in reversed(self.color_infos) if s == stamp), read_with)

    def _emit(self, waiting: _Waiting) -> RGBDFrame | None:
        """The frame of one depth message seen by its camera (the camera info of its stamp: a frame waits for its
        colour partner, and a later camera info may come meanwhile), or None (counted in stats) when it has no
        pose, no valid pixel, or no colour while colour is required."""
        index, stamp, msg, cam = waiting.index, waiting.stamp, waiting.msg, waiting.cam
        cloud_color = None
        if self.cloud:
            depth, cloud_color = decode_cloud(msg, f"{self.rec.path}: depth topic {self.depth_topic}")
        else:
            depth = decode_depth(msg, f"{self.rec.path}: {self.depth_topic}")
            if depth.size == 0:  # no image at all, not one without readings: its size would scale K to zeros
                self.stats.drop(DROP_NO_PIXELS)
                return None
            if self.unit_factor is not None and str(getattr(msg, "encoding", "")) in ("16UC1", "mono16"):
                depth *= self.unit_factor
        over = int(np.count_nonzero(depth >= np.float32((MAX_16BIT_MM - 0.5) / 1000)))
        if over:  # millimetres rounded to 65535 or more: "no measurement" in a 16-bit image (kinfu export)
            self.stats.pixels_over_16bit_mm += over
            self.stats.frames_over_16bit_mm += 1
        h, w = depth.shape
        K = cam.K
        if cam.width and cam.height and (w, h) != (cam.width, cam.height):
            K = self._scaled_K(w, h, cam)
        depth = cam.lens.image(depth)
        T = None
        if self.pose_fn is not None:
            T = self.pose_fn(stamp)
            if T is None:
                return None
        if not np.any(depth > 0):
            self.stats.drop(DROP_EMPTY)
            return None
        color = color_mask = None
        unpaired = False
        if self.color_topic is None and cloud_color is not None:
            color = cloud_color  # registered: the same pixels
        elif self.color_topic is not None and self.registration_mode() != "none":
            own = [c for c in self.colors if c[3] == waiting.color_pass]  # not another pass's, of another clock
            best_stamp, _, best, _, read_with = min(own, key=lambda c: abs(c[0] - stamp)) if own else (None,) * 5
            if self._lost_nearer_color(stamp, best_stamp):
                self.stats.color_cut_short += 1
            if best_stamp is not None and abs(best_stamp - stamp) > self.tol_ns:
                gap, seen = abs(best_stamp - stamp), self.stats.color_nearest_ns
                self.stats.color_nearest_ns = gap if seen is None else min(seen, gap)
            unpaired = best_stamp is None or abs(best_stamp - stamp) > self.tol_ns
            if not unpaired:
                where = f"{self.rec.path}: {self.color_topic}"
                color = decode_color(best, where)
                if color.size == 0:  # no image at all: as if unpaired, said in a warning
                    self.stats.color_empty += 1
                    self.stats.color_topic = self.color_topic
                    color = None
                elif self.registration_mode() == "project":
                    try:
                        reg = self._color_camera(best_stamp, read_with)
                        color, color_mask = register_color(reg, depth, K, color, where)
                    except ColorSizeError:  # the images changed size mid-run: no colour from here on
                        self._lose_color(color.shape[1::-1], index)
                        color = color_mask = None
                elif cam.color_K is not None:  # a rectified topic: undistorted already, onto P
                    color = reproject_pinhole(color, cam.color_K, cam.K, (cam.width, cam.height))
                elif not self._rectified_color():  # the depth camera's own pixels: its lens too
                    color = cam.lens.image(color, size_of_K=(cam.width, cam.height))
        if color is None:
            if self.require_color:
                self.stats.drop(DROP_NO_COLOR)
                return None
            self.stats.without_color += 1
            self.stats.color_unpaired += unpaired
        self.stats.used += 1
        return RGBDFrame(index=index, stamp_ns=stamp, depth=depth, color=color, K=K.copy(), T_world_camera=T,
                         color_mask=color_mask)

    def _lost_nearer_color(self, stamp: int, best_stamp: int | None) -> bool:
        """Whether a colour image dropped by the look-ahead was within the tolerance of `stamp` and nearer than
        `best_stamp` (the nearest kept one, None for none): a farther neighbour lost costs the frame nothing. A run's
        ends are dropped stamps; inside a run, where its images lie is not kept, so a nearer one is assumed."""
        reach = self.tol_ns if best_stamp is None else min(self.tol_ns, abs(best_stamp - stamp) - 1)
        return reach >= 0 and any(first - reach <= stamp <= last + reach for first, last in self.dropped_colors)

    def registration_mode(self) -> str:
        """How colour images map onto the depth: "same-frame", "project" or "none" (left out)."""
        return "same-frame" if self.registration is None else self.registration.mode

    def _lose_color(self, size: tuple[int, int], index: int) -> None:
        """Colour images that stopped fitting their camera info (register_color could place none): the colour is
        left out from depth frame `index` on, with the reason in stats (the warning of FrameStats.warnings)."""
        reason = f"{color_size_reason(self.color_topic, size, self.registration)} from depth frame {index} on"
        self.registration = replace(self.registration, mode="none", reason=reason)
        self.stats.color_registration = self.registration.as_dict()

    def _scaled_K(self, w: int, h: int, cam: _Camera) -> np.ndarray:
        """K for depth images of w x h whose camera info is for another size with the same aspect ratio (a
        decimation filter, image_proc's resize), said once in stats.notes; RecordingError otherwise, and when the
        camera info's roi / binning say which part of the sensor the images are."""
        sx, sy = w / cam.width, h / cam.height
        said = f"camera info {self.info_topic}" if self.info_topic else "the first depth image"
        if abs(sx - sy) > 0.01 * max(sx, sy) or not self.info_topic or cam.lens or cam.reduction:
            reduced = f" ({cam.reduction})" if cam.reduction else ""
            raise RecordingError(f"{self.rec.path}: depth image on {self.depth_topic} is {w}x{h} but {said} "
                                 f"says {cam.width}x{cam.height}{reduced}")
        K = scaled_intrinsics(cam.K, (sx, sy))
        note = (f"depth images on {self.depth_topic} are {w}x{h} but {said} says {cam.width}x{cam.height}: "
                f"its intrinsics were scaled by {sx:.4g}")
        if note not in self.stats.notes:
            self.stats.notes.append(note)
        return K

    def _forget_colors(self, log_ns: int) -> None:
        """Forget colour images logged over COLOR_LOOKAHEAD_NS ago that no waiting frame can use (a depth message
        that still wants one comes too late: counted when it does). Not by the latest depth stamp: a depth image
        logged after a later-stamped one wants the colour of its own."""
        waiting = min((w.stamp for w in self.pending), default=None)
        bounds = [s for s in (waiting, self.depth_stamp) if s is not None]
        runs, gap = self.dropped_colors, 2 * self.tol_ns
        while bounds and runs and runs[0][1] < min(bounds) - self.tol_ns:
            runs.popleft()
        while self.colors and self.colors[0][1] < log_ns - COLOR_LOOKAHEAD_NS and (
                waiting is None or self.colors[0][0] < waiting - self.tol_ns):
            stamp, _, _, color_pass, _ = self.colors.popleft()
            if color_pass != self.color_pass:
                continue  # of another clock: no frame to come lost it
            if runs and runs[-1][0] - gap <= stamp <= runs[-1][1] + gap:
                runs[-1] = [min(runs[-1][0], stamp), max(runs[-1][1], stamp)]
            else:
                runs.append([stamp, stamp])

    def _flush(self, up_to: int | None, settled_only: bool = True) -> Iterator[RGBDFrame]:
        """Emit waiting depth frames, in log order, whose colour partner can no longer arrive (all when up_to is
        None; those of an earlier colour pass too) and, unless not settled_only, whose camera info is settled."""
        pending = self.pending
        while pending and (pending[0].info_until is None or not settled_only) and (
                up_to is None or pending[0].stamp + self.tol_ns < up_to or pending[0].color_pass != self.color_pass):
            frame = self._emit(pending.popleft())
            if frame is not None:
                yield frame

    def _flush_ready(self) -> Iterator[RGBDFrame]:
        """Emit the waiting frames that a settled camera info made ready: without colour; with colour, the next
        colour image says (a depth clock that went back may be followed by the colour's)."""
        if self.color_topic is None:
            yield from self._flush(None)
