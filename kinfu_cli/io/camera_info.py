"""Camera intrinsics read from a recording's sensor_msgs/CameraInfo, for the images published with it.

A CameraInfo holds the calibration of the full sensor (K, D, P for width x height). Its images may be a region of
interest of that sensor (`roi`, in full-resolution pixels) and binned (`binning_x`, `binning_y`), and an image on a
rectified topic (image_proc's `image_rect`, iai_kinect2's `image_depth_rect`, RealSense's `image_rect_raw`) has
already been undistorted onto P's pinhole camera. `image_camera` reads a CameraInfo as ROS's image_geometry
PinholeCameraModel does (fromCameraInfo): binning 0 is 1, an roi of zeros is the full image; the roi offset moves
the principal point, then binning divides fx, cx (fy, cy); a rectified image is projected with P, without D.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.messages import camera_info_distortion, camera_info_K
from kinfu_cli.io.recording import open_recording

# a rectified image topic: "rect" as a word of its name (image_rect, image_rect_raw, image_depth_rect, image_rect_color)
_RECT_TOPIC = re.compile(r"(^|[/_])rect(ified)?([/_]|$)", re.I)
_FORM_TOLERANCE = 1e-6  # relative: entries of K that the pinhole form [fx s cx; 0 fy cy; 0 0 1] fixes


class ImageCamera(NamedTuple):
    """The pinhole camera of the images published with a CameraInfo."""

    K: np.ndarray  # 3x3 [fx 0 cx; 0 fy cy; 0 0 1] in the published images' pixels
    width: int  # size of the published images (the roi's, binned)
    height: int
    model: str  # lens distortion model, "" for none (io.undistort.check_distortion)
    D: np.ndarray
    reduction: str  # how the published images differ from the calibrated sensor ("" when they are all of it)
    notes: list[str]  # what is doubtful or was assumed (P for a rectified image), to say once


def is_rectified_topic(topic: str | None) -> bool:
    """Whether an image topic's name says its images are rectified (undistorted onto the camera info's P)."""
    return bool(topic) and _RECT_TOPIC.search(topic) is not None


def camera_matrix_problem(K: np.ndarray) -> str | None:
    """Why K is not a pinhole camera matrix [fx 0 cx; 0 fy cy; 0 0 1] (None when it is). Fusion, ICP and ray casting
    read fx, fy, cx, cy alone: a skew or a last row other than [0 0 1] would be dropped without a word."""
    fx, fy = abs(K[0, 0]), abs(K[1, 1])
    wrong = []
    if abs(K[0, 1]) > _FORM_TOLERANCE * fx:
        wrong.append(f"skew K[0,1]={K[0, 1]:g}")
    if abs(K[1, 0]) > _FORM_TOLERANCE * fy:
        wrong.append(f"K[1,0]={K[1, 0]:g}")
    for (i, j), want in (((2, 0), 0.0), ((2, 1), 0.0), ((2, 2), 1.0)):
        if abs(K[i, j] - want) > _FORM_TOLERANCE:
            wrong.append(f"K[{i},{j}]={K[i, j]:g}")
    if wrong:
        return (f"K is not a pinhole camera matrix [fx 0 cx; 0 fy cy; 0 0 1] ({', '.join(wrong)}; K = "
                f"{np.round(K, 6).tolist()})")
    return None


def principal_point_note(K: np.ndarray, width: int, height: int, image_topic: str | None) -> str | None:
    """A warning when K's principal point is off its width x height image (a lens's optical axis meets the sensor
    near its centre: K for another resolution?); None when it is on it or the size is unknown."""
    cx, cy = K[0, 2], K[1, 2]
    if width <= 0 or height <= 0 or (0 <= cx <= width and 0 <= cy <= height):
        return None
    images = f"the images on {image_topic}" if image_topic else "the images"
    return (f"the camera info of {images} has its principal point cx={cx:g}, cy={cy:g} outside its {width}x{height} "
            f"image (K for another resolution?); they are read with it all the same")


def _roi_binning(msg: object, width: int, height: int, where: str) -> tuple[int, int, int, int, int, int]:
    """(x_offset, y_offset, roi width, roi height, binning x, binning y) as image_geometry reads them: binning 0 is
    1, an roi of zeros is the full image; RecordingError naming `where` for an roi outside the image."""
    bx, by = (int(getattr(msg, n, 0) or 0) or 1 for n in ("binning_x", "binning_y"))
    roi = getattr(msg, "roi", None)
    x, y, rw, rh = ((int(getattr(roi, n, 0) or 0) for n in ("x_offset", "y_offset", "width", "height"))
                    if roi is not None else (0, 0, 0, 0))
    if (x, y, rw, rh) == (0, 0, 0, 0):
        return 0, 0, width, height, bx, by
    if rw < 1 or rh < 1 or (width and height and (x + rw > width or y + rh > height)):
        raise RecordingError(f"{where}: CameraInfo roi {rw}x{rh} at ({x}, {y}) is not inside its {width}x{height} "
                             f"image (expected the region of the calibrated image that is published)")
    return x, y, rw, rh, bx, by


def image_camera(msg: object, where: str, image_topic: str | None = None,
                 distortion=camera_info_distortion) -> ImageCamera:
    """The pinhole camera of the images on `image_topic` that `msg` (a sensor_msgs/CameraInfo) describes, read as
    image_geometry's PinholeCameraModel does: K (P for a rectified topic, is_rectified_topic, with no distortion)
    moved by the roi offset and divided by the binning; width x height the roi's size over the binning.
    distortion: reads (model, D) from the message. RecordingError naming `where` for a K that is not a pinhole
    camera matrix (camera_matrix_problem). A rectified topic's images are P's alone: its K need not be valid."""
    if not is_rectified_topic(image_topic):
        K, width, height = camera_info_K(msg, where)
        if (problem := camera_matrix_problem(K)) is not None:
            raise RecordingError(f"{where}: CameraInfo {problem}")
        model, D = distortion(msg, where)
        notes = []
    else:
        P, width, height = _rectified_P(msg, where, image_topic)
        try:  # K is not what its images are read with: a K of zeros (some drivers') is said, not refused
            K, _, _ = camera_info_K(msg, where)
            unused = "" if camera_matrix_problem(K) is None else ", not a pinhole camera matrix"
        except RecordingError as exc:
            K, unused = None, exc.detail.removeprefix(f"{where}: ")
        model, D = distortion(msg, where)
        notes = []
        if K is None or unused or model or not np.allclose(P, K, rtol=1e-9, atol=1e-9):
            with_k = (f"not with K ({unused})" if K is None else f"not with K (fx={K[0, 0]:.6g}, cx={K[0, 2]:.6g}"
                      f"{unused})") + (f" and its {model} D" if model else "")
            notes.append(f"the images on {image_topic} are rectified (by the topic's name): read with their "
                         f"camera info's projection matrix P (fx={P[0, 0]:.6g}, fy={P[1, 1]:.6g}, cx={P[0, 2]:.6g}, "
                         f"cy={P[1, 2]:.6g}) and no lens distortion, as image_geometry does, {with_k}")
        K, model, D = P, "", np.zeros(0)
    if (off := principal_point_note(K, width, height, image_topic)) is not None:
        notes.append(off)
    x, y, rw, rh, bx, by = _roi_binning(msg, width, height, where)
    K = K.copy()
    K[0, 2] -= x
    K[1, 2] -= y
    K[0, :3] /= bx
    K[1, :3] /= by
    parts = ([f"roi {rw}x{rh} at ({x}, {y})"] if (rw, rh) != (width, height) else []) + (
        [f"binning {bx}x{by}"] if (bx, by) != (1, 1) else [])
    reduction = f"{' and '.join(parts)} of {width}x{height}" if parts else ""
    return ImageCamera(K, rw // bx if parts else width, rh // by if parts else height, model, D, reduction, notes)


def _rectified_P(msg: object, where: str, image_topic: str) -> tuple[np.ndarray, int, int]:
    """(P[:, :3], width, height) of a CameraInfo whose images are rectified; RecordingError naming `where` when P
    is not a pinhole camera of positive focal lengths and a plausible field of view (camera_info_K's checks)."""
    try:
        P, width, height = camera_info_K(msg, where, matrix="P")
    except RecordingError as exc:
        raise RecordingError(f"{exc.detail}, and {image_topic} is rectified (its name): its images are P's pinhole "
                             f"camera") from None
    if (problem := camera_matrix_problem(P)) is not None:
        raise RecordingError(f"{where}: CameraInfo P: {problem.replace('K is', 'P[:, :3] is', 1)}")
    return P, width, height


def intrinsics_from_recording(path: str | os.PathLike) -> dict:
    """fx, fy, cx, cy, width, height from the first sensor_msgs/CameraInfo of a recording (MCAP, ROS 1
    .bag or ROS 2 bag folder, read with the project's recording reader): the depth camera's camera info that
    detect_roles finds, read as fuse reads it (image_camera: roi, binning, P for a rectified depth topic); the
    only or first depth-named one when no depth topic has one. The size and intrinsics are those of the published
    images."""
    from kinfu_cli.io.pointcloud2 import POINTCLOUD2
    from kinfu_cli.io.roles import detect_roles  # roles reads camera infos with image_camera

    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording")
    with open_recording(path) as rec:
        topics = rec.topics_of_type("sensor_msgs/msg/CameraInfo")
        if not topics:
            raise RecordingError(f"{path}: no sensor_msgs/CameraInfo topic; intrinsics missing "
                                 "(give fx, fy, cx, cy)")
        roles = detect_roles(rec, world_frame="")  # no world frame: only the camera's topics are wanted
        topic, image_topic = roles.info_topic, roles.depth_topic
        if topic is None:
            topic, image_topic = ([t for t in topics if "depth" in t] or topics)[0], None
        elif image_topic in rec.topics and POINTCLOUD2 in rec.topics[image_topic].msgtypes:
            image_topic = None  # a cloud's camera info is read with K, as fuse reads it
        msg = rec.first_message(topic)
        if msg is None:
            raise RecordingError(f"{path}: topic {topic} has no messages; intrinsics missing")
        K, w, h, *_ = image_camera(msg, f"{path}: {topic}", image_topic)
    return dict(fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]), cy=float(K[1, 2]), width=w, height=h)
