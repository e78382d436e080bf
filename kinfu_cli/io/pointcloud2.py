"""An organized sensor_msgs/PointCloud2 as a depth image: many recordings hold only the driver's cloud.

A camera driver's (or depth_image_proc's) organized cloud is the depth image lifted to points: height x width =
the image, NaN where there is no reading, points in the optical frame, so z per pixel is the depth and
x/z = (u - cx)/fx, y/z = (v - cy)/fy hold exactly. The intrinsics can then be recovered from one cloud by least
squares; a cloud that does not fit (transformed into another frame, filtered, re-sorted) is refused. An
unorganized cloud (height 1: a lidar, a segmented cluster) has no pixel grid and is not a depth source.

Fields are read with one numpy structured dtype (their offsets, point_step, row_step and byte order as
the message says), never point by point. The `rgb` / `rgba` field, as PCL packs it (0x00RRGGBB in a float32 or
uint32), is the colour of each pixel, already registered to the depth.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.errors import RecordingError

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
# sensor_msgs/PointField datatypes
_DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
_DATATYPE_OF = {v: k for k, v in _DATATYPES.items()}
MAX_PINHOLE_RMS_PX = 0.05  # a driver's cloud fits to float rounding (~1e-4 px); a transformed one by pixels
MIN_FIT_PIXELS = 16
COLOR_FIELDS = ("rgb", "rgba")


def is_cloud(msg: object) -> bool:
    """Whether a decoded message is a PointCloud2 (by its fields: ROS 1 and ROS 2 decoders name them alike)."""
    return hasattr(msg, "point_step") and hasattr(msg, "fields") and hasattr(msg, "row_step")


def _fields(msg: object) -> dict[str, tuple[int, int]]:
    """name -> (offset, datatype) of the message's PointFields."""
    return {str(f.name): (int(f.offset), int(f.datatype)) for f in msg.fields}


def has_color(msg: object) -> bool:
    return any(name in COLOR_FIELDS for name in _fields(msg))


def organized_problem(msg: object) -> str | None:
    """Why a cloud cannot be a depth image (unorganized, or no x/y/z float fields), or None."""
    h, w = int(msg.height), int(msg.width)
    fields = _fields(msg)
    if h <= 1:
        return (f"is an unorganized point cloud (height 1, {w} points): kinfu needs depth images or an organized "
                f"cloud (height x width = the depth image, points in the camera's optical frame)")
    missing = [n for n in "xyz" if n not in fields or fields[n][1] not in (7, 8)]
    if missing:
        return f"has no float32/float64 {'/'.join(missing)} field (fields: {', '.join(fields) or 'none'})"
    return None


def _structured(msg: object, names: tuple[str, ...], where: str) -> np.ndarray:
    """(H, W) structured view of the message's data holding `names` (fields not in the cloud left out), honouring
    offsets, point_step, row_step padding and byte order; no copy."""
    fields = _fields(msg)
    h, w, step, row = int(msg.height), int(msg.width), int(msg.point_step), int(msg.row_step)
    order = ">" if msg.is_bigendian else "<"
    names = tuple(n for n in names if n in fields)
    formats = []
    for n in names:
        off, dt = fields[n]
        if dt not in _DATATYPES:
            raise RecordingError(f"{where}: point field {n!r} has unknown datatype {dt}")
        size = int(_DATATYPES[dt][1])
        if n in COLOR_FIELDS:  # packed 0x00RRGGBB: the bits, whatever type names them
            if size != 4:
                raise RecordingError(f"{where}: colour field {n!r} is {size} bytes, expected a packed 4-byte rgb")
            formats.append(order + "u4")
        else:
            formats.append(order + _DATATYPES[dt])
        if off < 0 or off + size > step:
            raise RecordingError(f"{where}: point field {n!r} at offset {off} does not fit point_step {step}")
    buf = np.frombuffer(msg.data if isinstance(msg.data, (bytes, bytearray, memoryview, np.ndarray))
                        else bytes(msg.data), dtype=np.uint8)
    need = (h - 1) * row + w * step if h > 0 and w > 0 else 0
    if min(h, w, step, row) < 0 or row < w * step or buf.size < need:
        raise RecordingError(f"{where}: point cloud data has {buf.size} bytes, expected {h} rows of {w} points "
                             f"of {step} bytes (row_step {row})")
    dtype = np.dtype({"names": list(names), "formats": formats,
                      "offsets": [fields[n][0] for n in names], "itemsize": step})
    return np.ndarray((h, w), dtype=dtype, buffer=buf, strides=(row, step))


def decode_cloud(msg: object, where: str = "cloud") -> tuple[np.ndarray, np.ndarray | None]:
    """(float32 (H, W) depth in metres, 0 where x, y or z is not finite or z <= 0; uint8 (H, W, 3) RGB from the
    rgb/rgba field, or None) of an organized cloud. RecordingError naming `where` for any other cloud."""
    problem = organized_problem(msg)
    if problem:
        raise RecordingError(f"{where} {problem}")
    arr = _structured(msg, ("x", "y", "z", *COLOR_FIELDS), where)
    with np.errstate(invalid="ignore", over="ignore"):  # garbage bits (a wrong byte order) may be signalling NaNs
        x, y, z = (arr[n].astype(np.float32) for n in "xyz")
        ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(z) & (z > 0)
    depth = np.where(ok, z, np.float32(0.0)).astype(np.float32)
    color = None
    name = next((n for n in COLOR_FIELDS if n in arr.dtype.names), None)
    if name is not None:
        bits = arr[name].astype(np.uint32)
        color = np.stack([(bits >> 16) & 255, (bits >> 8) & 255, bits & 255], axis=-1).astype(np.uint8)
    return depth, color


def _rays(msg: object, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, x/z, y/z) of the cloud's valid pixels (float64)."""
    problem = organized_problem(msg)
    if problem:
        raise RecordingError(f"{where} {problem}")
    arr = _structured(msg, ("x", "y", "z"), where)
    with np.errstate(invalid="ignore", over="ignore"):  # garbage bits (a wrong byte order): signalling NaNs, 1e38
        x, y, z = (arr[n].astype(np.float64) for n in "xyz")
        ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(z) & (z > 0)
        v, u = np.nonzero(ok)
        a, b = x[ok] / z[ok], y[ok] / z[ok]
        keep = np.isfinite(a) & np.isfinite(b)
    return u[keep].astype(np.float64), v[keep].astype(np.float64), a[keep], b[keep]


def pinhole_rms(msg: object, K: np.ndarray, where: str = "cloud") -> float:
    """RMS distance (pixels) between each valid point of an organized cloud projected with K and its own pixel;
    inf without a valid point."""
    u, v, a, b = _rays(msg, where)
    if u.size == 0:
        return float("inf")
    K = np.asarray(K, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # rays of 1e30: a miss of inf pixels, said as inf
        du, dv = K[0, 0] * a + K[0, 2] - u, K[1, 1] * b + K[1, 2] - v
        rms = float(np.sqrt(np.mean(du * du + dv * dv)))
    return rms if np.isfinite(rms) else float("inf")


def fit_intrinsics(msg: object, where: str = "cloud") -> tuple[tuple[float, float, float, float], float]:
    """((fx, fy, cx, cy), RMS residual in pixels) fitted by least squares to u = fx x/z + cx, v = fy y/z + cy over
    the valid pixels of an organized cloud. RecordingError naming `where` when too few pixels (or too few rows or
    columns) are valid, or the cloud is no pinhole projection of its pixel grid (residual over
    MAX_PINHOLE_RMS_PX)."""
    u, v, a, b = _rays(msg, where)
    if u.size < MIN_FIT_PIXELS or np.ptp(u) < 2 or np.ptp(v) < 2:
        raise RecordingError(f"{where}: too few valid points ({u.size}) in the first cloud to recover the camera "
                             f"intrinsics; give them (fx,fy,cx,cy) or a camera info topic")
    params, res2 = [], 0.0
    with np.errstate(over="ignore", invalid="ignore"):  # rays of 1e30 (garbage bits): an inf residual, refused
        for pix, ray in ((u, a), (v, b)):  # a straight line pix = f ray + c, in closed form (centred sums)
            dr, dp = ray - ray.mean(), pix - pix.mean()
            f = float(dr @ dp) / float(dr @ dr) if float(dr @ dr) > 0 else 0.0
            c = float(pix.mean() - f * ray.mean())
            params.append((f, c))
            r = dp - f * dr
            res2 += float(r @ r) / r.size
    (fx, cx), (fy, cy) = params
    rms = float(np.sqrt(res2))
    if not (rms <= MAX_PINHOLE_RMS_PX and fx > 0 and fy > 0):
        raise RecordingError(f"{where}: the cloud is not a pinhole projection of its pixel grid (x/z, y/z fit the "
                             f"pixels to {rms:.3g} px RMS, more than {MAX_PINHOLE_RMS_PX}): a transformed or "
                             f"filtered cloud; kinfu needs the camera's organized cloud in its optical frame")
    return (fx, fy, cx, cy), rms


def organized_cloud(depth: np.ndarray, K: np.ndarray, color: np.ndarray | None = None, float_type: str = "f4",
                    byteorder: str = "<", pad: int = 0) -> np.ndarray:
    """The (H, W) structured array of an organized cloud as a driver writes it: x, y, z (NaN where depth is 0)
    and, with `color` (uint8 (H, W, 3)), a packed float32 `rgb`; `pad` bytes at the end of each point
    (for RecordingWriter.write_pointcloud2; tests and synthetic recordings)."""
    depth = np.asarray(depth, dtype=np.float64)
    h, w = depth.shape
    K = np.asarray(K, dtype=np.float64)
    v, u = np.mgrid[0:h, 0:w]
    z = np.where(depth > 0, depth, np.nan)
    size = np.dtype(float_type).itemsize
    names, formats, offsets = ["x", "y", "z"], [byteorder + float_type] * 3, [0, size, 2 * size]
    if color is not None:
        names.append("rgb")
        formats.append(byteorder + "f4")
        offsets.append(4 * size)  # PCL's layout: x y z, a pad word, then rgb
    itemsize = (offsets[-1] + (4 if color is not None else size)) + int(pad)
    arr = np.zeros((h, w), np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize}))
    arr["x"], arr["y"], arr["z"] = (u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z
    if color is not None:
        c = np.asarray(color, dtype=np.uint32)
        arr["rgb"].view(byteorder + "u4")[...] = (c[..., 0] << 16) | (c[..., 1] << 8) | c[..., 2]  # bits, not values
    return arr


def point_fields(dtype: np.dtype) -> list[tuple[str, int, int]]:
    """(name, offset, PointField datatype) of each field of a structured dtype."""
    out = []
    for name in dtype.names:
        sub, off = dtype.fields[name][:2]
        out.append((name, int(off), _DATATYPE_OF[sub.kind + str(sub.itemsize)]))
    return out
