"""Write recordings: MCAP (ROS 2 cdr), ROS 1 .bag and ROS 2 bag folders, through rosbags.

`RecordingWriter(path)` picks the container from the name: `.mcap` -> one MCAP file (rosbags' ROS 2 writer
with mcap storage), `.bag` -> ROS 1 bag (rosbags.rosbag1.Writer), anything else -> a ROS 2 bag folder
(sqlite3 storage). The output appears only when the writer closes without an error (temp then rename).

Stamps are int nanoseconds; transforms are 4x4 float matrices, `T_parent_child` (maps child into parent).
"""

from __future__ import annotations

import contextlib
import os
import struct
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np

from kinfu_cli.core.errors import ConfigError, RecordingError
from kinfu_cli.core.atomic import atomic_dir, atomic_path, scratch_dir
from kinfu_cli.core.file_kinds import FILE_SUFFIXES
from kinfu_cli.core.poses import matrix_to_quaternion

FORMATS = ("mcap", "bag", "ros2", "ros2-mcap")  # ros2-mcap: a ROS 2 bag folder with mcap storage

# Image encodings we write: numpy dtype and channel count.
_IMAGE_ENCODINGS = {
    "16UC1": (np.uint16, 1),
    "32FC1": (np.float32, 1),
    "rgb8": (np.uint8, 3),
    "bgr8": (np.uint8, 3),
    "rgba8": (np.uint8, 4),
    "bgra8": (np.uint8, 4),
    "mono8": (np.uint8, 1),
    "mono16": (np.uint16, 1),
}

_TFMESSAGE_ROS1 = "geometry_msgs/TransformStamped[] transforms\n"


def format_for(path: str | os.PathLike, fmt: str | None = None) -> str:
    """Container for `path`: 'mcap', 'bag' or 'ros2' (sqlite3 folder); `fmt` overrides the suffix (and is the
    only way to ask for 'ros2-mcap', a ROS 2 bag folder with mcap storage). A ROS 2 bag is a folder: a path named
    like a file (results.json, depth.png, x.mcap asked for as 'ros2') is refused rather than made a folder of that
    name."""
    if fmt is not None and fmt not in FORMATS:
        raise ConfigError(f"recording format {fmt!r}: expected one of {', '.join(FORMATS)}", parameter="fmt")
    suffix = Path(path).suffix.lower()
    kind = fmt or {".mcap": "mcap", ".bag": "bag"}.get(suffix, "ros2")
    if kind.startswith("ros2") and suffix in FILE_SUFFIXES:
        raise ConfigError(f"{os.fspath(path)} names a {suffix} file, but a ROS 2 bag is a folder; expected NAME.mcap, "
                          f"NAME.bag or a folder name without that suffix", parameter="path")
    return kind


class RecordingWriter:
    """Context manager writing ROS messages into a new recording.

    >>> with RecordingWriter("out.mcap") as w:
    ...     w.write_image("/camera/depth/image_raw", t_ns, "camera_optical", depth_mm, "16UC1")

    compression: None, or "zstd" (MCAP chunks / ROS 2 storage), "lz4"/"bz2" (ROS 1 chunks).
    """

    def __init__(self, path: str | os.PathLike, fmt: str | None = None, compression: str | None = None,
                 force: bool = False):
        self.path = Path(path)
        self.force = force  # a ROS 2 bag folder replacing one: a user's entry with a new file's name is replaced
        self.fmt = format_for(self.path, fmt)
        self.compression = compression
        self._stack: contextlib.ExitStack | None = None
        self._writer = None
        self._typestore = None
        self._connections: dict[tuple[str, str], object] = {}
        self._seq: dict[str, int] = {}
        self._bag_dir: Path | None = None
        self._target: Path | None = None
        self.counts: dict[str, int] = {}

    # ----------------------------------------------------------------------------------- lifecycle
    def __enter__(self) -> "RecordingWriter":
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close(failed=exc_type is not None)

    def open(self) -> None:
        # rosbags takes a good part of a second to import: only when a recording is written
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        stack = contextlib.ExitStack()
        try:
            if self.fmt == "bag":
                self._typestore = get_typestore(Stores.ROS1_NOETIC)
                self._typestore.register(get_types_from_msg(_TFMESSAGE_ROS1, "tf2_msgs/msg/TFMessage"))
                tmp = stack.enter_context(atomic_path(self.path))
                tmp.unlink()  # rosbags refuses to overwrite
                writer = Writer1(tmp)
                if self.compression:
                    comp = {"lz4": Writer1.CompressionFormat.LZ4, "bz2": Writer1.CompressionFormat.BZ2}
                    if self.compression not in comp:
                        raise ConfigError(f"compression {self.compression!r} for a .bag: expected lz4 or bz2")
                    writer.set_compression(comp[self.compression])
            else:
                self._typestore = get_typestore(Stores.ROS2_HUMBLE)
                if self.fmt == "mcap":
                    # rosbags writes a bag folder holding <name>.mcap; the file alone is a complete MCAP.
                    self._target = stack.enter_context(atomic_path(self.path))
                    tmp_dir = stack.enter_context(scratch_dir(self.path))  # a killed run's is cleared next time
                    self._bag_dir = tmp_dir / self.path.stem
                    writer = Writer2(self._bag_dir, version=9, storage_plugin=StoragePlugin.MCAP)
                else:
                    # rosbags names the storage file after its folder: write tmp/<name>/, move it up at close
                    self._target = stack.enter_context(atomic_dir(self.path, force=self.force))
                    self._bag_dir = self._target / self.path.name
                    plugin = StoragePlugin.MCAP if self.fmt == "ros2-mcap" else StoragePlugin.SQLITE3
                    writer = Writer2(self._bag_dir, version=9, storage_plugin=plugin)
                if self.compression:
                    if self.compression != "zstd":
                        raise ConfigError(f"compression {self.compression!r} for ROS 2 / MCAP: expected zstd")
                    writer.set_compression(CompressionMode.STORAGE if self.fmt in ("mcap", "ros2-mcap")
                                           else CompressionMode.MESSAGE, CompressionFormat.ZSTD)
            writer.open()
        except BaseException as exc:
            stack.__exit__(type(exc), exc, exc.__traceback__)
            raise
        self._writer = writer
        self._stack = stack

    def close(self, failed: bool = False) -> None:
        """Finish the container; on success rename it into place, on failure remove the partial output."""
        stack, self._stack = self._stack, None
        if stack is None:
            return
        try:
            if failed:
                with contextlib.suppress(Exception):
                    getattr(self._writer, "abort", self._writer.close)()
                raise _Abort
            self._writer.close()
            if self.fmt == "mcap":
                os.replace(self._bag_dir / f"{self._bag_dir.name}.mcap", self._target)
            elif self.fmt in ("ros2", "ros2-mcap"):  # a ROS 2 bag folder
                for item in self._bag_dir.iterdir():  # bag files up into the folder that becomes `path`
                    os.replace(item, self._target / item.name)
                self._bag_dir.rmdir()
                umask = os.umask(0)
                os.umask(umask)
                self._target.chmod(0o777 & ~umask)  # mkdtemp made it 0700
        except BaseException as exc:
            try:
                stack.__exit__(type(exc), exc, exc.__traceback__)
            except _Abort:
                return
            if isinstance(exc, _Abort):
                return
            raise
        stack.close()

    # ----------------------------------------------------------------------------------- plumbing
    def _conn(self, topic: str, msgtype: str):
        key = (topic, msgtype)
        conn = self._connections.get(key)
        if conn is None:
            if self._writer is None:
                raise RecordingError(f"{self.path}: writer is not open")
            conn = self._writer.add_connection(topic, msgtype, typestore=self._typestore)
            self._connections[key] = conn
        return conn

    def _write(self, topic: str, msgtype: str, stamp_ns: int, msg: object, trailer: bytes = b"") -> None:
        conn = self._conn(topic, msgtype)
        if self.fmt == "bag":
            data = self._typestore.serialize_ros1(msg, msgtype)
        else:
            data = self._typestore.serialize_cdr(msg, msgtype)
        self._writer.write(conn, int(stamp_ns), bytes(data) + trailer if trailer else data)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def _type(self, name: str):
        return self._typestore.types[name]

    def _time(self, stamp_ns: int):
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        return self._type("builtin_interfaces/msg/Time")(sec=sec, nanosec=nsec)

    def _header(self, topic: str, stamp_ns: int, frame_id: str):
        header_t = self._type("std_msgs/msg/Header")
        if self.fmt == "bag":
            seq = self._seq.get(topic, 0)
            self._seq[topic] = seq + 1
            return header_t(seq=seq, stamp=self._time(stamp_ns), frame_id=frame_id)
        return header_t(stamp=self._time(stamp_ns), frame_id=frame_id)

    def _transform(self, T: np.ndarray):
        T = _as_pose(T)
        q = matrix_to_quaternion(T[:3, :3])
        vec = self._type("geometry_msgs/msg/Vector3")(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3]))
        quat = self._type("geometry_msgs/msg/Quaternion")(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                          w=float(q[3]))
        return self._type("geometry_msgs/msg/Transform")(translation=vec, rotation=quat)

    # ----------------------------------------------------------------------------------- messages
    def write_image(self, topic: str, stamp_ns: int, frame_id: str, array: np.ndarray, encoding: str,
                    trailer: bytes = b"", log_ns: int | None = None) -> None:
        """sensor_msgs/Image; `array` must match `encoding` (16UC1 uint16 mm, 32FC1 float32 m, rgb8 ...).
        trailer: bytes after the message (recent librealsense versions append a float32 depth_units); log_ns:
        when the recorder logged it (default its stamp; a driver's latency logs it later)."""
        if encoding not in _IMAGE_ENCODINGS:
            raise ConfigError(f"image encoding {encoding!r}: expected one of {', '.join(_IMAGE_ENCODINGS)}")
        dtype, channels = _IMAGE_ENCODINGS[encoding]
        arr = np.asarray(array)
        if arr.ndim == 2 and channels == 1:
            pass
        elif arr.ndim == 3 and arr.shape[2] == channels:
            pass
        else:
            raise ConfigError(f"{topic}: array shape {arr.shape} does not fit encoding {encoding}")
        arr = np.ascontiguousarray(arr.astype(dtype, copy=False))
        if arr.dtype.byteorder == ">":
            arr = arr.astype(arr.dtype.newbyteorder("<"))
        h, w = arr.shape[:2]
        msg = self._type("sensor_msgs/msg/Image")(
            header=self._header(topic, stamp_ns, frame_id), height=h, width=w, encoding=encoding,
            is_bigendian=0, step=w * channels * arr.dtype.itemsize,
            data=np.frombuffer(arr.tobytes(), dtype=np.uint8))
        self._write(topic, "sensor_msgs/msg/Image", stamp_ns if log_ns is None else log_ns, msg, trailer)

    def write_compressed_image(self, topic: str, stamp_ns: int, frame_id: str, rgb_uint8: np.ndarray,
                               fmt: str = "jpeg", quality: int = 95) -> None:
        """sensor_msgs/CompressedImage of an RGB (H,W,3) or mono (H,W) uint8 image, jpeg or png."""
        fmt = fmt.lower()
        if fmt not in ("jpeg", "jpg", "png"):
            raise ConfigError(f"{topic}: compressed format {fmt!r}: expected jpeg or png")
        img = np.asarray(rgb_uint8)
        if img.dtype != np.uint8:
            raise ConfigError(f"{topic}: compressed colour must be uint8, got {img.dtype}")
        bgr = cv2.cvtColor(img, cv2.COLOR_RGB2BGR) if img.ndim == 3 else img
        ext = ".png" if fmt == "png" else ".jpg"
        params = [cv2.IMWRITE_JPEG_QUALITY, int(quality)] if ext == ".jpg" else []
        ok, buf = cv2.imencode(ext, bgr, params)
        if not ok:
            raise RecordingError(f"{topic}: could not encode the image as {fmt}")
        enc = "bgr8" if img.ndim == 3 else "mono8"
        msg = self._type("sensor_msgs/msg/CompressedImage")(
            header=self._header(topic, stamp_ns, frame_id),
            format=f"{enc}; {'png' if ext == '.png' else 'jpeg'} compressed {enc}",
            data=buf.reshape(-1).astype(np.uint8))
        self._write(topic, "sensor_msgs/msg/CompressedImage", stamp_ns, msg)

    def write_compressed_bytes(self, topic: str, stamp_ns: int, frame_id: str, data: bytes, fmt: str) -> None:
        """sensor_msgs/CompressedImage from already-encoded jpeg/png bytes (no re-encoding, e.g. a data set's
        own files). fmt: "jpeg" or "png"."""
        fmt = "jpeg" if fmt.lower() in ("jpg", "jpeg") else fmt.lower()
        if fmt not in ("jpeg", "png"):
            raise ConfigError(f"{topic}: compressed format {fmt!r}: expected jpeg or png")
        msg = self._type("sensor_msgs/msg/CompressedImage")(
            header=self._header(topic, stamp_ns, frame_id), format=f"rgb8; {fmt} compressed bgr8",
            data=np.frombuffer(bytes(data), dtype=np.uint8))
        self._write(topic, "sensor_msgs/msg/CompressedImage", stamp_ns, msg)

    def write_compressed_depth(self, topic: str, stamp_ns: int, frame_id: str, depth_uint16_mm: np.ndarray) -> None:
        """image_transport compressedDepth: a 12-byte ConfigHeader (format, depthParam[2]) then a 16-bit PNG."""
        depth = np.asarray(depth_uint16_mm)
        if depth.ndim != 2 or depth.dtype != np.uint16:
            raise ConfigError(f"{topic}: compressed depth must be a (H,W) uint16 array in mm, got "
                              f"{depth.dtype} {depth.shape}")
        ok, buf = cv2.imencode(".png", depth, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise RecordingError(f"{topic}: could not encode the depth image as PNG")
        # ConfigHeader {int32 format (0 = INV_DEPTH as image_transport writes it); float depthParam[2]}
        config = struct.pack("<iff", 0, 0.0, 0.0)
        data = np.frombuffer(config + buf.tobytes(), dtype=np.uint8)
        msg = self._type("sensor_msgs/msg/CompressedImage")(
            header=self._header(topic, stamp_ns, frame_id), format="16UC1; compressedDepth png", data=data)
        self._write(topic, "sensor_msgs/msg/CompressedImage", stamp_ns, msg)

    def write_pointcloud2(self, topic: str, stamp_ns: int, frame_id: str, points: np.ndarray,
                          row_pad: int = 0) -> None:
        """sensor_msgs/PointCloud2 of a structured (H, W) array (io.pointcloud2.organized_cloud): its fields,
        offsets, itemsize (point_step) and byte order as they are; `row_pad` bytes after each row."""
        from kinfu_cli.io.pointcloud2 import point_fields

        pts = np.asarray(points)
        if pts.dtype.names is None or pts.ndim != 2:
            raise ConfigError(f"{topic}: expected a structured (H, W) array, got {pts.dtype} {pts.shape}")
        orders = {pts.dtype.fields[n][0].byteorder for n in pts.dtype.names} - {"|", "="}
        big = orders == {">"}
        h, w = pts.shape
        step = pts.dtype.itemsize
        rows = np.zeros((h, w * step + int(row_pad)), np.uint8)
        rows[:, : w * step] = np.ascontiguousarray(pts).view(np.uint8).reshape(h, w * step)
        field_t = self._type("sensor_msgs/msg/PointField")
        fields = [field_t(name=n, offset=off, datatype=dt, count=1) for n, off, dt in point_fields(pts.dtype)]
        msg = self._type("sensor_msgs/msg/PointCloud2")(
            header=self._header(topic, stamp_ns, frame_id), height=h, width=w, fields=fields, is_bigendian=big,
            point_step=step, row_step=rows.shape[1], data=rows.reshape(-1), is_dense=False)
        self._write(topic, "sensor_msgs/msg/PointCloud2", stamp_ns, msg)

    def write_camera_info(self, topic: str, stamp_ns: int, frame_id: str, K: np.ndarray, width: int,
                          height: int, D: np.ndarray | None = None, model: str = "plumb_bob",
                          log_ns: int | None = None) -> None:
        """sensor_msgs/CameraInfo with `model` distortion D (zeros when None), R = I, P = [K | 0]; log_ns as
        write_image's."""
        K = np.asarray(K, dtype=np.float64).reshape(3, 3)
        D = np.zeros(5) if D is None else np.asarray(D, dtype=np.float64).reshape(-1)
        P = np.zeros((3, 4))
        P[:, :3] = K
        roi = self._type("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0,
                                                             do_rectify=False)
        names = ("D", "K", "R", "P") if self.fmt == "bag" else ("d", "k", "r", "p")
        fields = dict(zip(names, (D, K.reshape(-1), np.eye(3).reshape(-1), P.reshape(-1))))
        msg = self._type("sensor_msgs/msg/CameraInfo")(
            header=self._header(topic, stamp_ns, frame_id), height=int(height), width=int(width),
            distortion_model=model, binning_x=0, binning_y=0, roi=roi, **fields)
        self._write(topic, "sensor_msgs/msg/CameraInfo", stamp_ns if log_ns is None else log_ns, msg)

    def write_tf(self, stamp_ns: int, transforms: list[tuple[str, str, np.ndarray]], static: bool = False) -> None:
        """tf2_msgs/TFMessage on /tf (or /tf_static): each (parent, child, T_parent_child)."""
        topic = "/tf_static" if static else "/tf"
        items = []
        for parent, child, T in transforms:
            items.append(self._type("geometry_msgs/msg/TransformStamped")(
                header=self._header(topic, stamp_ns, parent), child_frame_id=child,
                transform=self._transform(T)))
        msg = self._type("tf2_msgs/msg/TFMessage")(transforms=items)
        self._write(topic, "tf2_msgs/msg/TFMessage", stamp_ns, msg)

    def write_transform(self, topic: str, stamp_ns: int, T: np.ndarray) -> None:
        """A bare geometry_msgs/Transform of the 4x4 T (no header: the RealSense SDK's stream extrinsics)."""
        self._write(topic, "geometry_msgs/msg/Transform", stamp_ns, self._transform(T))

    def write_float32(self, topic: str, stamp_ns: int, value: float) -> None:
        """std_msgs/Float32 (the RealSense SDK's option values, e.g. Depth Units)."""
        self._write(topic, "std_msgs/msg/Float32", stamp_ns, self._type("std_msgs/msg/Float32")(data=float(value)))

    def write_vector(self, topic: str, stamp_ns: int, frame_id: str, v) -> None:
        """geometry_msgs/Vector3Stamped of the 3-vector v in `frame_id`."""
        x, y, z = (float(c) for c in np.asarray(v, dtype=np.float64).reshape(3))
        vec = self._type("geometry_msgs/msg/Vector3")(x=x, y=y, z=z)
        msg = self._type("geometry_msgs/msg/Vector3Stamped")(header=self._header(topic, stamp_ns, frame_id),
                                                             vector=vec)
        self._write(topic, "geometry_msgs/msg/Vector3Stamped", stamp_ns, msg)

    def write_pose(self, topic: str, stamp_ns: int, frame_id: str, T: np.ndarray) -> None:
        """geometry_msgs/PoseStamped of the 4x4 pose T (pose of the object in `frame_id`)."""
        T = _as_pose(T)
        q = matrix_to_quaternion(T[:3, :3])
        point = self._type("geometry_msgs/msg/Point")(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3]))
        quat = self._type("geometry_msgs/msg/Quaternion")(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                          w=float(q[3]))
        pose = self._type("geometry_msgs/msg/Pose")(position=point, orientation=quat)
        msg = self._type("geometry_msgs/msg/PoseStamped")(header=self._header(topic, stamp_ns, frame_id),
                                                           pose=pose)
        self._write(topic, "geometry_msgs/msg/PoseStamped", stamp_ns, msg)


class _Abort(Exception):
    """Internal: the block writing the recording failed; discard the output."""


def _as_pose(T: np.ndarray) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConfigError(f"transform must be a finite 4x4 matrix, got shape {T.shape}")
    return T
