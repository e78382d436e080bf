"""RealSense SDK recordings: the .bag the RealSense Viewer or librealsense's recorder writes (ROS 1 bag, SDK layout).

The SDK writes its own topics, not a ROS driver's (librealsense, src/media/readme.md "Realsense Record and
Playback"): each stream's images on /device_<d>/sensor_<s>/<Stream>_<n>/image/data (depth: mono16 / 16UC1 in
*depth units*), its camera info on .../info/camera_info, each sensor's options as std_msgs/Float32 on
/device_<d>/sensor_<s>/option/<name>/value (the depth sensor's "Depth Units": metres per unit, 0.001 unless set
otherwise, 0.0001 on a D405 or in high-accuracy presets), and each stream's extrinsics as a bare
geometry_msgs/Transform on .../<Stream>_<n>/tf/<group>. There is no /tf and the header frame_ids are empty, so
the generic reader would read the depth as millimetres and the colour as the depth camera's own pixels (resized),
though the colour camera sits ~15 mm beside the depth camera with its own intrinsics.

Extrinsics direction (librealsense's ros_writer writes `device::get_extrinsics(stream)`, which fetches the
extrinsics *from* the extrinsics group's reference ("pin") stream *to* the stream; rs2_extrinsics maps a point
p_from to R p_from + t, and the quaternion is written from that R): the transform on .../tf/<group> is
T_stream_reference. So the colour camera's T_color_depth = T_color_ref @ inv(T_depth_ref) for the same group.
"""

from __future__ import annotations

import re

import numpy as np

from kinfu_cli.core.errors import KinfuError, RecordingError
from kinfu_cli.io.messages import transform_to_matrix
from kinfu_cli.io.undistort import check_distortion

DEFAULT_DEPTH_UNITS = 0.001  # m per unit: the SDK's default for the D400 series
_IMAGE = re.compile(r"^/device_(\d+)/sensor_(\d+)/([A-Za-z]+)_(\d+)/image/data$")
_TF = re.compile(r"/tf/(\d+)$")
TRANSFORM = "geometry_msgs/msg/Transform"
MAX_EXTRINSIC_OFFSET_M = 10.0  # two streams of one device sit centimetres apart; more is a damaged record
# the SDK's distortion model names (rs2_distortion_to_string) as OpenCV projects points (librealsense's
# rs2_project_point_to_pixel): Brown-Conrady is plumb_bob; the inverse and modified forms differ from it only in
# the tangential term taking the radially distorted x, y (second order in p1, p2, ~1e-4 on a D400 colour camera)
SDK_DISTORTION = {"brown conrady": "plumb_bob", "inverse brown conrady": "plumb_bob",
                  "modified brown conrady": "plumb_bob", "kannala brandt4": "equidistant"}


def sdk_image(deserialize, raw, msgtype: str):
    """A ROS 1 sensor_msgs/Image as recent librealsense versions write it (src/media/ros/ros_writer.cpp sets
    header.version "1", and its bundled sensor_msgs/Image serializer then appends a float32 depth_units after the
    pixel data, under the standard definition and MD5), which a strict reader refuses as a size mismatch: decoded
    without those 4 bytes, their value kept as the message's `depth_units` (m per unit, 0 for colour). None when
    the message is no such image."""
    if not msgtype.endswith("sensor_msgs/msg/Image") or len(raw) < 4:
        return None
    try:
        msg = deserialize(bytes(raw[:-4]), msgtype)
    except Exception:  # not the SDK's trailer either: the caller reports the first error
        return None
    msg.depth_units = float(f"{float(np.frombuffer(bytes(raw[-4:]), '<f4')[0]):.7g}")
    return msg


def _stream_prefix(image_topic: str) -> str:
    return image_topic[: -len("/image/data")]


def _sensor_prefix(image_topic: str) -> str:
    return image_topic.rsplit("/", 3)[0]


def image_streams(rec) -> dict[str, list[str]]:
    """Stream type (Depth, Color, Infrared, ...) -> its image topics with messages, in device/sensor/index
    order; empty when the recording has none in the SDK's layout."""
    found: dict[str, list[tuple[tuple[int, int, int], str]]] = {}
    for name, info in rec.topics.items():
        m = _IMAGE.match(name)
        if m and info.count:
            found.setdefault(m.group(3), []).append(((int(m.group(1)), int(m.group(4)), int(m.group(2))), name))
    return {k: [n for _, n in sorted(v)] for k, v in found.items()}


def is_sdk_recording(rec) -> bool:
    """Whether the recording is in the RealSense SDK's layout (depth images on /device_<d>/.../Depth_<n>)."""
    return bool(image_streams(rec).get("Depth"))


def sdk_topic_roles(rec) -> dict[str, str | None]:
    """The depth, colour and depth camera info topics of an SDK recording (the first Depth and Color streams)."""
    streams = image_streams(rec)
    depth = (streams.get("Depth") or [None])[0]
    color = (streams.get("Color") or [None])[0]
    info = None
    if depth is not None and f"{_stream_prefix(depth)}/info/camera_info" in rec.topics:
        info = f"{_stream_prefix(depth)}/info/camera_info"
    return {"depth_topic": depth, "color_topic": color, "info_topic": info}


def is_sdk_stream(rec, image_topic: str | None) -> bool:
    """Whether `image_topic` is an SDK stream's image topic (the depth topic chosen may be another one)."""
    return image_topic is not None and bool(_IMAGE.match(image_topic)) and image_topic in rec.topics


def depth_units(rec, depth_topic: str) -> tuple[float, str, str | None]:
    """(metres per depth unit, where it comes from, a note or None) for an SDK depth stream: the depth sensor's
    "Depth Units" option (SDK versions write it with a space or an underscore), else the depth_units a recent SDK
    appends to its depth images (sdk_image); 1 mm assumed, with a note, when neither is recorded. RecordingError
    naming the topic for a value that is no plausible scale. When the option changes during the recording the
    first value is used, with a note."""
    sensor = _sensor_prefix(depth_topic)
    for topic in (f"{sensor}/option/Depth Units/value", f"{sensor}/option/Depth_Units/value"):
        if topic not in rec.topics or not rec.topics[topic].count:
            continue
        values = [_option_value(msg, f"{rec.path}: {topic}") for _, _, msg in rec.messages([topic])]
        first = values[0] if values else float("nan")
        if not (np.isfinite(first) and 1e-7 <= first <= 0.1):
            raise RecordingError(f"{rec.path}: {topic}: depth units {first} m per unit is no depth scale "
                                 f"(expected e.g. 0.001)")
        note = None
        if any(abs(v - first) > 1e-9 for v in values[1:]):
            note = (f"the depth units change during the recording ({', '.join(f'{v:g}' for v in values[:5])}"
                    f"{', ...' if len(values) > 5 else ''} m); the first, {first:g} m, is used for every frame")
        return first, topic, note
    first = rec.first_message(depth_topic)  # recent SDK versions also append it to each depth image
    units = float(getattr(first, "depth_units", 0.0) or 0.0) if first is not None else 0.0
    if np.isfinite(units) and 1e-7 <= units <= 0.1:
        return units, f"{depth_topic} (depth_units)", None
    return DEFAULT_DEPTH_UNITS, "assumed", (
        f"RealSense SDK recording without the depth sensor's Depth Units option ({sensor}/option/Depth Units/"
        f"value): {DEFAULT_DEPTH_UNITS * 1000:g} mm per unit assumed")


def _option_value(msg: object, where: str) -> float:
    """An SDK option's value (std_msgs/Float32; NaN without a `data` field); RecordingError naming `where` for a
    value that is no number (another message type on the option's topic)."""
    raw = getattr(msg, "data", np.nan)
    try:
        return float(f"{float(raw):.7g}")  # float32 on the wire: 7 significant digits (0.0001, not 9.9999997e-05)
    except (TypeError, ValueError):
        raise RecordingError(f"{where}: depth units {raw!r} is no number (expected metres per unit, e.g. "
                             f"0.001)") from None


def stream_extrinsics(rec, image_topic: str) -> dict[int, np.ndarray]:
    """Extrinsics group -> T_stream_reference (4x4: maps the group's reference stream's points into this
    stream's frame) of an SDK stream, from its .../tf/<group> topics (the first message of each)."""
    out = {}
    for name in _tf_topics(rec, image_topic):
        msg = rec.first_message(name)
        if msg is None or not hasattr(msg, "rotation"):
            continue
        try:
            T = transform_to_matrix(msg)
        except KinfuError:  # a zero or NaN quaternion: this group's extrinsics are unusable, like a NaN offset
            continue
        if (np.all(np.isfinite(T)) and abs(np.linalg.det(T[:3, :3]) - 1.0) < 1e-3
                and np.abs(T[:3, 3]).max() <= MAX_EXTRINSIC_OFFSET_M):
            out[int(_TF.search(name).group(1))] = T
    return out


def _tf_topics(rec, image_topic: str) -> list[str]:
    prefix = f"{_stream_prefix(image_topic)}/tf/"
    return [n for n, info in rec.topics.items() if n.startswith(prefix) and _TF.search(n) and info.count]


def sdk_distortion(info: object, where: str) -> tuple[str, np.ndarray]:
    """(OpenCV model, D) of an SDK camera info, whose distortion_model is the SDK's name (SDK_DISTORTION); a
    ROS name passes as it is. RecordingError naming `where` for another model with non-zero D."""
    model = str(getattr(info, "distortion_model", "") or "")
    d = getattr(info, "d", None)
    d = getattr(info, "D", None) if d is None else d
    return check_distortion(SDK_DISTORTION.get(model.strip().lower(), model), d, where)


def _stream_name(image_topic: str) -> str:
    return _stream_prefix(image_topic).rsplit("/", 1)[-1]


def sdk_color_registration(rec, depth_topic: str, color_topic: str) -> ColorRegistration:
    """How an SDK colour stream maps onto the depth stream: projected through the colour stream's camera info and
    the two streams' extrinsics (same group); mode "none" with the reason when either is missing."""
    from kinfu_cli.io.color_registration import ColorRegistration, colour_camera  # (it imports io.roles: us)

    d_name, c_name = _stream_name(depth_topic), _stream_name(color_topic)
    info_topic = f"{_stream_prefix(color_topic)}/info/camera_info"
    if info_topic not in rec.topics or not rec.topics[info_topic].count:
        return ColorRegistration("none", d_name, c_name, reason=f"the RealSense colour stream {c_name} has no "
                                 f"camera info ({info_topic})")
    try:
        lens, (w, h) = colour_camera(rec, info_topic, sdk_distortion)
    except RecordingError as exc:  # a broken colour calibration costs the colour, not the run
        return ColorRegistration("none", d_name, c_name, info_topic, reason=str(exc))
    ext_d, ext_c = stream_extrinsics(rec, depth_topic), stream_extrinsics(rec, color_topic)
    common = sorted(set(ext_d) & set(ext_c))
    if not common:
        missing = [f"{_stream_prefix(t)}/tf/<group>" for t, e in ((depth_topic, ext_d), (color_topic, ext_c))
                   if not e and not _tf_topics(rec, t)]
        broken = [n for t, e in ((depth_topic, ext_d), (color_topic, ext_c)) if not e for n in _tf_topics(rec, t)]
        why = (f"no extrinsics recorded ({', '.join(missing)})" if missing else
               f"unusable extrinsics ({', '.join(broken)}: not a finite rigid transform within "
               f"{MAX_EXTRINSIC_OFFSET_M:g} m)" if broken else
               f"their extrinsics are to different reference streams (groups {sorted(ext_d)} and {sorted(ext_c)})")
        return ColorRegistration("none", d_name, c_name, info_topic, reason=f"the RealSense colour stream "
                                 f"{c_name} cannot be placed on the depth stream {d_name}: {why}")
    g = common[0]
    T_color_depth = ext_c[g] @ np.linalg.inv(ext_d[g])
    return ColorRegistration("project", d_name, c_name, info_topic, lens, (w, h), T_color_depth)


def sdk_summary(rec, depth_topic: str | None, color_topic: str | None) -> dict | None:
    """What `kinfu info` says of an SDK recording: the layout, the depth scale and where the colour goes; None
    when the depth topic is no SDK stream."""
    if not is_sdk_stream(rec, depth_topic):
        return None
    out: dict = {"layout": "RealSense SDK recording (librealsense / RealSense Viewer .bag)"}
    try:
        units, source, note = depth_units(rec, depth_topic)
        out.update(depth_units_m=units, depth_units_source=source, notes=[note] if note else [])
    except RecordingError as exc:
        out.update(problem=str(exc), notes=[])
    if color_topic is not None and is_sdk_stream(rec, color_topic):
        out["color_registration"] = sdk_color_registration(rec, depth_topic, color_topic).as_dict()
    return out
