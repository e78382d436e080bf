"""Decode ROS messages into arrays: depth and colour images, camera intrinsics, poses and stamps.

Works on messages decoded by rosbags (ROS 1 and ROS 2 field names) and by mcap-ros1-support
(byte strings, `secs`/`nsecs` stamps). Depth comes out as float32 metres with 0 = invalid.
"""

from __future__ import annotations

import contextlib
import os
import struct
import sys
from collections.abc import Iterator

import cv2
import numpy as np

from kinfu_cli.core.camera import field_of_view_problem
from kinfu_cli.core.errors import RecordingError
from kinfu_cli.core.poses import quaternion_to_matrix
from kinfu_cli.io.undistort import check_distortion

DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")
COLOR_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8", "8UC3", "8UC1", "yuv422", "uyvy", "yuv422_yuy2",
                   "yuyv", "bayer_rggb8", "bayer_bggr8", "bayer_gbrg8", "bayer_grbg8", "rgb16", "bgr16", "mono16")
# OpenCV's Bayer codes name the pattern from the second row and column: ROS's bayer_rggb8 is OpenCV's BayerBG
_BAYER = {"bayer_rggb8": cv2.COLOR_BayerBG2RGB, "bayer_bggr8": cv2.COLOR_BayerRG2RGB,
          "bayer_gbrg8": cv2.COLOR_BayerGR2RGB, "bayer_grbg8": cv2.COLOR_BayerGB2RGB}
_YUV = {"yuv422": cv2.COLOR_YUV2RGB_UYVY, "uyvy": cv2.COLOR_YUV2RGB_UYVY, "yuv422_yuy2": cv2.COLOR_YUV2RGB_YUY2,
        "yuyv": cv2.COLOR_YUV2RGB_YUY2}
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------------------------------------- image codecs
@contextlib.contextmanager
def _c_stderr_silenced() -> Iterator[None]:
    """Point file descriptor 2 at /dev/null for the block. libpng prints its own "libpng error/warning" lines
    with fprintf(stderr) (OpenCV leaves libpng's default handlers in place, and no log level reaches them), and
    OpenCV's logger writes "[ WARN...]" lines there too: on corrupt data they would land before kinfu's one
    error line. Without a usable descriptor 2 the block just runs."""
    try:
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):
        pass
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 2)
        finally:
            os.close(devnull)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


c_stderr_silenced = _c_stderr_silenced  # for other C readers (open3d's RPly prints "RPly: ..." lines itself)


def imdecode_quiet(data: np.ndarray | bytes, flags: int) -> np.ndarray | None:
    """cv2.imdecode of encoded image bytes (None when they do not decode), without the codec libraries'
    messages on stderr."""
    buf = np.frombuffer(data, dtype=np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) else data
    if buf.size == 0:
        return None
    with _c_stderr_silenced():
        return cv2.imdecode(buf, flags)


def imread_quiet(path: str | os.PathLike, flags: int) -> np.ndarray | None:
    """An image file decoded as cv2.imread would (None when it is missing, unreadable or does not decode),
    without the codec libraries' messages on stderr."""
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except (OSError, ValueError):
        return None
    return imdecode_quiet(data, flags)


# ------------------------------------------------------------------------------------------- stamps
def time_to_ns(t: object) -> int:
    """ROS time (builtin_interfaces Time, rospy/genpy Time) -> int nanoseconds."""
    if hasattr(t, "nanosec"):
        return int(t.sec) * 1_000_000_000 + int(t.nanosec)
    if hasattr(t, "nsecs"):
        return int(t.secs) * 1_000_000_000 + int(t.nsecs)
    if hasattr(t, "to_nsec"):
        return int(t.to_nsec())
    if isinstance(t, (int, np.integer)):
        return int(t)
    raise RecordingError(f"cannot read a timestamp from {type(t).__name__}")


def header_stamp_ns(msg: object) -> int | None:
    """Header stamp of a message in ns, or None when it has no header or the stamp is zero."""
    header = getattr(msg, "header", None)
    if header is None:
        return None
    ns = time_to_ns(header.stamp)
    return ns if ns > 0 else None


def header_frame(msg: object) -> str:
    header = getattr(msg, "header", None)
    return str(getattr(header, "frame_id", "") or "") if header is not None else ""


def _xyz(v: object) -> list[float]:
    return [float(v.x), float(v.y), float(v.z)]


def _xyzw(q: object) -> list[float]:
    return [float(q.x), float(q.y), float(q.z), float(q.w)]


def transform_to_matrix(transform: object) -> np.ndarray:
    """geometry_msgs/Transform -> 4x4."""
    T = np.eye(4)
    T[:3, :3] = quaternion_to_matrix(_xyzw(transform.rotation))
    T[:3, 3] = _xyz(transform.translation)
    return T


def pose_to_matrix(pose: object) -> np.ndarray:
    """geometry_msgs/Pose -> 4x4."""
    T = np.eye(4)
    T[:3, :3] = quaternion_to_matrix(_xyzw(pose.orientation))
    T[:3, 3] = _xyz(pose.position)
    return T


POSE_TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/TransformStamped",
)


def pose_message_to_matrix(msg: object, msgtype: str) -> np.ndarray:
    """4x4 pose from a PoseStamped, PoseWithCovarianceStamped, Odometry or TransformStamped message."""
    name = normalize_msgtype(msgtype)
    if name == "geometry_msgs/msg/PoseStamped":
        return pose_to_matrix(msg.pose)
    if name in ("geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry"):
        return pose_to_matrix(msg.pose.pose)
    if name == "geometry_msgs/msg/TransformStamped":
        return transform_to_matrix(msg.transform)
    raise RecordingError(f"message type {msgtype}: expected one of {', '.join(POSE_TYPES)}")


def pose_message_to_tq(msg: object, msgtype: str) -> tuple[tuple[float, float, float],
                                                         tuple[float, float, float, float]]:
    """(translation xyz, quaternion xyzw) of a pose message, without building a matrix (for batches)."""
    name = normalize_msgtype(msgtype)
    if name == "geometry_msgs/msg/PoseStamped":
        p, q = msg.pose.position, msg.pose.orientation
    elif name in ("geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry"):
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
    elif name == "geometry_msgs/msg/TransformStamped":
        p, q = msg.transform.translation, msg.transform.rotation
    else:
        raise RecordingError(f"message type {msgtype}: expected one of {', '.join(POSE_TYPES)}")
    return (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)


def normalize_msgtype(msgtype: str) -> str:
    """'sensor_msgs/Image' or 'sensor_msgs/msg/Image' -> 'sensor_msgs/msg/Image'."""
    parts = msgtype.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return msgtype


# ------------------------------------------------------------------------------------------- images
def _bytes(data: object) -> np.ndarray:
    if isinstance(data, np.ndarray):
        return data.view(np.uint8).reshape(-1) if data.dtype != np.uint8 else data.reshape(-1)
    return np.frombuffer(bytes(data) if not isinstance(data, (bytes, bytearray, memoryview)) else data,
                         dtype=np.uint8)


def _raw_image(msg: object, dtype: np.dtype, channels: int, topic: str) -> np.ndarray:
    """Image rows (honouring `step` padding and byte order) -> (H, W[, C]) array of dtype."""
    dtype = np.dtype(dtype)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * channels * dtype.itemsize
    buf = _bytes(msg.data)
    if step < row or buf.size < step * h:
        raise RecordingError(f"{topic}: image data has {buf.size} bytes, expected {h} rows of {row} "
                             f"(step {step}) for {w}x{h} {msg.encoding}")
    if buf.size > step * h:  # another image's size or encoding, or two images: not its first rows (cv_bridge refuses)
        raise RecordingError(f"{topic}: image data has {buf.size} bytes, more than the {step * h} of {h} rows of "
                             f"step {step} for {w}x{h} {msg.encoding} (a wrong size or encoding?)")
    rows = buf[: step * h].reshape(h, step)[:, :row]
    arr = np.ascontiguousarray(rows).view(dtype.newbyteorder(">" if msg.is_bigendian else "<"))
    arr = arr.astype(dtype, copy=False)
    return arr.reshape(h, w, channels) if channels > 1 else arr.reshape(h, w)


def is_compressed(msg: object) -> bool:
    return hasattr(msg, "format") and not hasattr(msg, "encoding")


def decode_depth(msg: object, topic: str = "depth") -> np.ndarray:
    """sensor_msgs/Image (16UC1 mm, 32FC1 m) or compressedDepth CompressedImage -> float32 (H,W) metres.

    Invalid readings (0, NaN, inf, negative, 65535 mm) become 0.
    """
    if is_compressed(msg):
        return _decode_compressed_depth(msg, topic)
    enc = str(msg.encoding)
    if enc in ("16UC1", "mono16"):
        mm = _raw_image(msg, np.uint16, 1, topic)
        depth = mm.astype(np.float32) * np.float32(0.001)
        depth[mm == 65535] = 0.0
        return depth
    if enc == "32FC1":
        depth = _raw_image(msg, np.float32, 1, topic).copy()
        depth[~np.isfinite(depth) | (depth < 0)] = 0.0
        return depth
    raise RecordingError(f"{topic}: depth encoding {enc!r} is not supported (expected 16UC1 in mm, 32FC1 in m "
                         f"or a compressedDepth PNG / RVL)")


def _decode_compressed_depth(msg: object, topic: str) -> np.ndarray:
    fmt = str(msg.format)
    if "compresseddepth" not in fmt.lower():
        raise RecordingError(f"{topic}: compressed image format {fmt!r} is not depth (expected "
                             f"'16UC1; compressedDepth png' or '32FC1; compressedDepth')")
    raw = _bytes(msg.data).tobytes()
    if "rvl" in fmt.lower():
        from kinfu_cli.io.rvl import decode_rvl  # numba: only for the recordings that need it

        try:
            img, header = decode_rvl(raw)
        except ValueError as exc:
            raise RecordingError(f"{topic}: compressedDepth RVL data: {exc}") from None
    else:
        img, header = _compressed_depth_png(raw, topic)
    enc = fmt.split(";")[0].strip()
    if enc in ("16UC1", "mono16"):
        depth = img.astype(np.float32) * np.float32(0.001)
        depth[img == 65535] = 0.0
        return depth
    if enc == "32FC1":
        if header is None:
            raise RecordingError(f"{topic}: 32FC1 compressedDepth lacks its 12-byte quantisation header")
        _, a, b = struct.unpack("<iff", header)
        inv = img.astype(np.float32)
        depth = np.zeros(img.shape, np.float32)
        ok = img != 0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            depth[ok] = a / (inv[ok] - b)
        depth[~np.isfinite(depth) | (depth < 0)] = 0.0
        return depth
    raise RecordingError(f"{topic}: compressedDepth encoding {enc!r} is not supported (expected 16UC1 or 32FC1)")


def _compressed_depth_png(raw: bytes, topic: str) -> tuple[np.ndarray, bytes | None]:
    """(uint16 image, the 12-byte quantisation header before the PNG or None) of compressedDepth png data."""
    start = raw.find(_PNG_MAGIC)
    if start < 0:
        raise RecordingError(f"{topic}: compressedDepth message holds no PNG data")
    img = imdecode_quiet(np.frombuffer(raw[start:], dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise RecordingError(f"{topic}: compressedDepth PNG could not be decoded (truncated or corrupt image data)")
    if img.ndim != 2 or img.dtype != np.uint16:
        raise RecordingError(f"{topic}: compressedDepth PNG is not a 16-bit single-channel image")
    return img, (raw[start - 12:start] if start >= 12 else None)


def decode_color(msg: object, topic: str = "color") -> np.ndarray:
    """sensor_msgs/Image (COLOR_ENCODINGS: rgb/bgr/rgba/bgra/mono 8-bit, 16-bit rgb/bgr/mono, packed YUV 4:2:2,
    Bayer mosaics) or jpeg/png CompressedImage -> uint8 (H,W,3) RGB."""
    if is_compressed(msg):
        fmt = str(msg.format)
        if "compresseddepth" in fmt.lower():
            raise RecordingError(f"{topic}: compressed format {fmt!r} is depth, expected a jpeg/png colour image")
        # the pixels as stored, as image_transport decodes them: an EXIF orientation would turn them off the depth
        img = imdecode_quiet(_bytes(msg.data), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
        if img is None:
            raise RecordingError(f"{topic}: compressed image (format {fmt!r}) could not be decoded as jpeg/png")
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    enc = str(msg.encoding)
    if enc == "rgb8":
        return _raw_image(msg, np.uint8, 3, topic).copy()
    if enc in ("bgr8", "8UC3"):
        return _raw_image(msg, np.uint8, 3, topic)[:, :, ::-1].copy()
    if enc == "rgba8":
        return _raw_image(msg, np.uint8, 4, topic)[:, :, :3].copy()
    if enc == "bgra8":
        return _raw_image(msg, np.uint8, 4, topic)[:, :, 2::-1].copy()
    if enc in ("mono8", "8UC1"):
        return np.repeat(_raw_image(msg, np.uint8, 1, topic)[:, :, None], 3, axis=2)
    if enc.lower() in _YUV:  # a webcam's (usb_cam, v4l2) packed 4:2:2
        return cv2.cvtColor(_raw_image(msg, np.uint8, 2, topic), _YUV[enc.lower()])
    if enc in _BAYER:  # a machine-vision camera's raw mosaic
        return cv2.cvtColor(np.ascontiguousarray(_raw_image(msg, np.uint8, 1, topic)), _BAYER[enc])
    if enc in ("rgb16", "bgr16", "mono16"):
        img = (_raw_image(msg, np.uint16, 1 if enc == "mono16" else 3, topic) >> 8).astype(np.uint8)
        return np.repeat(img[:, :, None], 3, axis=2) if enc == "mono16" else np.ascontiguousarray(
            img if enc == "rgb16" else img[:, :, ::-1])
    raise RecordingError(f"{topic}: colour encoding {enc!r} is not supported (expected one of "
                         f"{', '.join(COLOR_ENCODINGS)}, or jpeg/png CompressedImage)")


def camera_info_distortion(msg: object, topic: str = "camera_info") -> tuple[str, np.ndarray]:
    """sensor_msgs/CameraInfo -> (distortion model, D): D empty when all zero (io.undistort.check_distortion)."""
    d = getattr(msg, "d", None)
    if d is None:
        d = getattr(msg, "D", None)
    return check_distortion(str(getattr(msg, "distortion_model", "") or ""), d, topic)


_K_NAMES = {(0, 0): "fx", (1, 1): "fy", (0, 2): "cx", (1, 2): "cy", (0, 1): "skew"}


def camera_info_K(msg: object, topic: str = "camera_info", matrix: str = "K") -> tuple[np.ndarray, int, int]:
    """sensor_msgs/CameraInfo -> (K 3x3 float64, width, height); matrix "P": the projection matrix's left 3x3
    instead (a rectified image's camera), with the same checks: positive finite focal lengths, a plausible field
    of view."""
    k = getattr(msg, matrix.lower(), None)
    if k is None:
        k = getattr(msg, matrix, None)
    if k is None:
        raise RecordingError(f"{topic}: message has no {matrix} matrix (expected sensor_msgs/CameraInfo)")
    K = np.asarray(list(k) if not isinstance(k, np.ndarray) else k, dtype=np.float64).reshape(-1)
    if K.size != (12 if matrix == "P" else 9):
        raise RecordingError(f"{topic}: CameraInfo {matrix} has {K.size} entries, expected "
                             f"{'3x4' if matrix == 'P' else '3x3'}")
    K = K.reshape(3, 4)[:, :3].copy() if matrix == "P" else K.reshape(3, 3)
    if not np.all(np.isfinite(K)):
        bad = ", ".join(f"{_K_NAMES.get((i, j), f'{matrix}[{i}][{j}]')}={K[i, j]}"
                        for i, j in zip(*np.nonzero(~np.isfinite(K))))
        raise RecordingError(f"{topic}: CameraInfo {matrix} has non-finite entries ({bad})")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise RecordingError(f"{topic}: CameraInfo {matrix} has no valid focal lengths (fx={K[0, 0]}, fy={K[1, 1]})")
    if (problem := field_of_view_problem(K, int(msg.width), int(msg.height))) is not None:
        raise RecordingError(f"{topic}: CameraInfo {matrix}: {problem}")
    return K, int(msg.width), int(msg.height)
