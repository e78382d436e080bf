"""Colour registered to depth: each depth pixel's colour, whether or not the colour camera is the depth camera.

A colour image is registered to the depth image when both are in the same optical frame (a Kinect's registered
mode, RealSense's aligned_depth_to_color topics): pixel (u, v) of one is pixel (u, v) of the other, and a
different size is a resize. A RealSense or Azure Kinect recording without alignment has its colour camera a few
centimetres away, with its own intrinsics and size: resizing would paint every surface with what lies beside it.
Then each depth pixel's 3-D point is projected into the colour camera (its camera info, and the TF from the depth
to the colour optical frame) and takes the colour there, unless the colour camera sees a nearer surface at that
pixel (a z-buffer of the projected depth: the colour camera's own occlusions). Pixels without colour are black
and False in the frame's colour mask, which fusion skips. When the colour camera's info or TF is missing, there is
no colour.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinfu_cli.core.camera import is_resized
from kinfu_cli.core.errors import RecordingError, TransformError
from kinfu_cli.io.camera_info import image_camera
from kinfu_cli.io.messages import decode_color, header_frame, is_compressed
from kinfu_cli.io.roles import CAMERA_INFO
from kinfu_cli.io.tf_buffer import TfBuffer
from kinfu_cli.io.undistort import Undistorter

class ColorSizeError(RecordingError):
    """A colour image whose size is not its camera info's, nor that camera resized (another aspect ratio): its
    pixels cannot be placed, so a reader leaves the colour out rather than the run."""


OCCLUSION_MARGIN = 0.02  # m: a point farther than the colour camera's nearest surface at its pixel by this is hidden


@dataclass
class ColorRegistration:
    """How colour images map onto the depth image: `mode` "same-frame" (pixel to pixel, resized), "project"
    (through K_color and T_color_depth) or "none" (no colour: `reason` says why)."""

    mode: str
    depth_frame: str = ""
    color_frame: str = ""
    info_topic: str | None = None
    lens: Undistorter | None = None  # the colour camera: its K and distortion (none: Undistorter.pinhole)
    color_size: tuple[int, int] | None = None  # (width, height) of the colour camera info
    T_color_depth: np.ndarray | None = None
    reason: str = ""

    @property
    def K_color(self) -> np.ndarray | None:
        return None if self.lens is None else self.lens.K

    def as_dict(self) -> dict:
        return {"mode": self.mode, "depth_frame": self.depth_frame, "color_frame": self.color_frame,
                "color_info_topic": self.info_topic, "reason": self.reason,
                **({"T_color_depth": np.round(self.T_color_depth, 6).tolist()} if self.T_color_depth is not None
                   else {})}


def color_registration(rec, depth_topic: str, color_topic: str, depth_info_topic: str,
                       tf: TfBuffer | None = None) -> ColorRegistration:
    """How the colour topic's images map onto the depth topic's (the first message of each names its frame);
    tf: the recording's TF (read from it when None and needed)."""
    first_depth, first_color = rec.first_message(depth_topic), rec.first_message(color_topic)
    d_frame = header_frame(first_depth).lstrip("/") if first_depth is not None else ""
    c_frame = header_frame(first_color).lstrip("/") if first_color is not None else ""
    if not d_frame or not c_frame or d_frame == c_frame:
        return ColorRegistration("same-frame", d_frame, c_frame)
    infos = [n for n, i in rec.topics.items() if CAMERA_INFO in i.msgtypes and i.count > 0 and n != depth_info_topic]
    info_topic = next((n for n in infos if header_frame(rec.first_message(n)).lstrip("/") == c_frame), None)
    if info_topic is None:
        return ColorRegistration("none", d_frame, c_frame, reason=f"the colour images are in frame {c_frame!r}, "
                                 f"the depth images in {d_frame!r}, and no camera info topic is in {c_frame!r}")
    try:
        lens, (w, h) = colour_camera(rec, info_topic, image_topic=color_topic)
    except RecordingError as exc:  # a broken colour calibration costs the colour, not the run
        return ColorRegistration("none", d_frame, c_frame, info_topic, reason=str(exc))
    tf = tf if tf is not None else TfBuffer.from_recording(rec)
    if not tf.connected(c_frame, d_frame):
        return ColorRegistration("none", d_frame, c_frame, info_topic, reason=f"no TF links the colour frame "
                                 f"{c_frame!r} to the depth frame {d_frame!r}")
    try:
        T = tf.lookup(c_frame, d_frame)
    except TransformError as exc:
        return ColorRegistration("none", d_frame, c_frame, info_topic, reason=str(exc))
    return ColorRegistration("project", d_frame, c_frame, info_topic, lens, (w, h), T)


def check_color_size(reg: ColorRegistration, rec, color_topic: str,
                     depth_size: tuple[int, int] | None = None) -> ColorRegistration:
    """`reg`, or no colour (mode "none", the reason naming the topic and both sizes) when the colour topic's first
    image is neither its camera info's size nor that size resized (register_color could place none of them), or,
    colour in the depth camera's own frame ("same-frame"), when it is not the depth image (depth_size: width,
    height) resized: another aspect ratio is another camera, and stretching it would paint colours beside their
    surfaces."""
    if reg.mode == "same-frame" and depth_size is not None and all(depth_size):
        size = _first_color_size(rec, color_topic)
        w, h = depth_size
        if size is None or is_resized(size, (w, h)):
            return reg
        return replace(reg, mode="none", reason=(
            f"the colour images on {color_topic} are {size[0]}x{size[1]} and the depth images {w}x{h} in the same "
            f"frame {reg.depth_frame!r}: another aspect ratio, so not the depth camera's pixels resized (a colour "
            "camera needs its own frame and camera info to be projected)"))
    if reg.mode != "project" or reg.color_size is None:
        return reg
    size = _first_color_size(rec, color_topic)
    if size is None:
        return reg
    if is_resized(size, reg.color_size):
        return reg
    return replace(reg, mode="none", reason=color_size_reason(color_topic, size, reg))


def _first_color_size(rec, color_topic: str) -> tuple[int, int] | None:
    """(width, height) of the colour topic's first image; None when there is none, it cannot be decoded (each frame
    says so itself) or it has no pixels."""
    msg = rec.first_message(color_topic)
    if msg is None:
        return None
    if is_compressed(msg):
        try:
            ch, cw = decode_color(msg, f"{rec.path}: {color_topic}").shape[:2]
        except RecordingError:  # a broken image: each frame says so itself
            return None
    else:
        cw, ch = int(getattr(msg, "width", 0)), int(getattr(msg, "height", 0))
    return (cw, ch) if cw >= 1 and ch >= 1 else None


def color_size_reason(color_topic: str, size: tuple[int, int], reg: ColorRegistration) -> str:
    """Why colour images of `size` (width, height) cannot be placed through `reg`'s camera info."""
    return (f"the colour images on {color_topic} are {size[0]}x{size[1]} but camera info {reg.info_topic} says "
            f"{reg.color_size[0]}x{reg.color_size[1]} (another aspect ratio: not that camera resized)")


def colour_camera(rec, info_topic: str, distortion=None,
                  image_topic: str | None = None) -> tuple[Undistorter, tuple[int, int]]:
    """The colour camera of `info_topic`'s first message for the images on `image_topic`: its lens (K and
    distortion, read by `distortion` when given) and image size, after the roi and binning (io.camera_info
    .image_camera; P and no distortion for a rectified topic); RecordingError naming the topic when it cannot be
    read."""
    return colour_camera_of(rec.first_message(info_topic), f"{rec.path}: {info_topic}", distortion, image_topic)


def colour_camera_of(info: object, where: str, distortion=None,
                     image_topic: str | None = None) -> tuple[Undistorter, tuple[int, int]]:
    """The colour camera of one camera info message `info` (colour_camera's reading); RecordingError naming
    `where` when it cannot be read."""
    cam = image_camera(info, where, image_topic, **({"distortion": distortion} if distortion else {}))
    w, h = cam.width, cam.height
    if w < 1 or h < 1:  # the colour pixels are scaled by the image's size over this one
        raise RecordingError(f"{where}: CameraInfo says the colour image is {w}x{h}; expected its width and "
                             f"height in pixels")
    return Undistorter(cam.K, cam.model, cam.D), (w, h)


def register_color(reg: ColorRegistration, depth: np.ndarray, K_depth: np.ndarray, color: np.ndarray,
                   where: str) -> tuple[np.ndarray, np.ndarray | None]:
    """(uint8 (H, W, 3) colour of each depth pixel of `depth` (metres, 0 = none), bool (H, W) mask of the pixels
    that have one (None: all)); black where there is none."""
    h, w = depth.shape
    ch, cw = color.shape[:2]
    if reg.mode != "project":
        return color, None
    sx, sy = cw / reg.color_size[0], ch / reg.color_size[1]
    if not is_resized((cw, ch), reg.color_size):
        raise ColorSizeError(f"{where}: colour image is {cw}x{ch} but camera info {reg.info_topic} says "
                             f"{reg.color_size[0]}x{reg.color_size[1]}")
    from kinfu_cli.io.color_kernels import colour_camera_points, pinhole_pixels, zbuffer_gather

    T = np.asarray(reg.T_color_depth, dtype=np.float64)
    pc = colour_camera_points(np.ascontiguousarray(depth, dtype=np.float32), np.asarray(K_depth, np.float64),
                              np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))
    if reg.lens:  # through the colour camera's lens (OpenCV's projection, C++)
        uv = np.full((len(pc), 2), -1.0)
        front = pc[:, 2] > 1e-6
        uv[front] = reg.lens.project(pc[front])
    else:
        uv = pinhole_pixels(pc, np.asarray(reg.K_color, np.float64))
    if (cw, ch) != reg.color_size:  # the same camera's image at another size: its pixels scale
        uv = np.where(uv >= 0, (uv + 0.5) * (sx, sy) - 0.5, -1.0)  # pixel centres kept (core.camera)
    return zbuffer_gather(pc, uv, np.ascontiguousarray(color[:, :, :3]), OCCLUSION_MARGIN, h, w)
