"""The NBV sensor model: pinhole intrinsics, image size, range limits, optional wider vertical FOV.

Camera frame is the optical frame (x right, y down, z forward). The paper tilts the sensor by
+-5 degrees about its horizontal axis at every viewpoint, so its NBV sensor model has a wider vertical
field of view; `vfov_extra_deg` adds that many degrees above and below by growing the image height at
the same focal length (`CameraModel.widened()`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinfu_cli.errors import ConfigError, RecordingError

# Kinect v1 (the paper's sensor) at 640x480: the usual ROS default calibration.
KINECT_V1 = dict(fx=525.0, fy=525.0, cx=319.5, cy=239.5, width=640, height=480)


@dataclass(frozen=True)
class CameraModel:
    """Pinhole depth sensor. fx, fy, cx, cy in pixels; width, height in pixels; ranges in metres
    (measured along each ray); vfov_extra_deg widens the vertical FOV on both sides."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    min_range: float = 0.5
    max_range: float = 4.0
    vfov_extra_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"--{name}: expected a positive focal length in pixels, got {v}")
        for name in ("cx", "cy"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"--{name}: expected a finite principal point, got {getattr(self, name)}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ConfigError(f"--width/--height: expected a positive image size, got {self.width}x{self.height}")
        if not (0 <= self.min_range < self.max_range) or not math.isfinite(self.max_range):
            raise ConfigError(f"--min-range/--max-range: expected 0 <= min < max, got {self.min_range}, "
                              f"{self.max_range}")
        if not (0 <= self.vfov_extra_deg < 45):
            raise ConfigError(f"--vfov-extra: expected 0 to 45 degrees, got {self.vfov_extra_deg}")

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)

    def widened(self) -> "CameraModel":
        """The same camera with `vfov_extra_deg` added above and below (taller image, same focal)."""
        if self.vfov_extra_deg <= 0:
            return self
        extra = math.radians(self.vfov_extra_deg)
        top = math.atan((self.cy + 0.5) / self.fy) + extra  # angle to the upper image edge
        bottom = math.atan((self.height - 0.5 - self.cy) / self.fy) + extra
        if top >= math.pi / 2 or bottom >= math.pi / 2:
            raise ConfigError("--vfov-extra: the widened vertical field of view reaches 180 degrees")
        add_top = int(math.ceil(self.fy * math.tan(top) - 0.5 - self.cy))
        add_bottom = int(math.ceil(self.fy * math.tan(bottom) + 0.5 + self.cy - self.height))
        return replace(self, cy=self.cy + add_top, height=self.height + add_top + add_bottom, vfov_extra_deg=0.0)

    def pixel_rays(self) -> np.ndarray:
        """(H*W, 3) unit ray directions in the camera frame, row-major (v, u)."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        d = np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u)], axis=-1).reshape(-1, 3)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def to_dict(self) -> dict:
        return {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy, "width": int(self.width),
                "height": int(self.height), "min_range": self.min_range, "max_range": self.max_range,
                "vfov_extra_deg": self.vfov_extra_deg}


def camera_from_options(fx: float | None = None, fy: float | None = None, cx: float | None = None,
                        cy: float | None = None, width: int | None = None, height: int | None = None,
                        camera_info: str | os.PathLike | None = None, min_range: float = 0.5,
                        max_range: float = 4.0, vfov_extra_deg: float = 0.0) -> CameraModel:
    """Build the sensor model from CLI options.

    Either all of fx, fy, cx, cy (width/height default 640x480), or `camera_info` (a recording with a
    sensor_msgs/CameraInfo topic), or none of them: then the Kinect v1 calibration the paper used.
    """
    given = {k: v for k, v in dict(fx=fx, fy=fy, cx=cx, cy=cy).items() if v is not None}
    if camera_info is not None:
        if given:
            raise ConfigError("--camera-info: give either a recording or --fx/--fy/--cx/--cy, not both")
        intr = intrinsics_from_recording(camera_info)
        if width is not None or height is not None:
            raise ConfigError("--width/--height: the image size comes from --camera-info; do not give both")
    elif given:
        missing = [f"--{k}" for k in ("fx", "fy", "cx", "cy") if k not in given]
        if missing:
            raise ConfigError(f"intrinsics missing: {', '.join(missing)} (give all of --fx --fy --cx --cy, "
                              "or --camera-info RECORDING)")
        intr = dict(given, width=640 if width is None else width, height=480 if height is None else height)
    else:
        intr = dict(KINECT_V1)
        if width is not None or height is not None:
            raise ConfigError("--width/--height need --fx --fy --cx --cy (or --camera-info) as well")
    return CameraModel(float(intr["fx"]), float(intr["fy"]), float(intr["cx"]), float(intr["cy"]),
                       int(intr["width"]), int(intr["height"]), float(min_range), float(max_range),
                       float(vfov_extra_deg))


def intrinsics_from_recording(path: str | os.PathLike) -> dict:
    """fx, fy, cx, cy, width, height from the first sensor_msgs/CameraInfo of a recording (MCAP, ROS 1
    .bag or ROS 2 bag folder, read with the project's recording reader); the depth camera's if several."""
    from kinfu_cli.io.messages import camera_info_K
    from kinfu_cli.io.recording import open_recording

    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording (--camera-info)")
    with open_recording(path) as rec:
        topics = rec.topics_of_type("sensor_msgs/msg/CameraInfo")
        if not topics:
            raise RecordingError(f"{path}: no sensor_msgs/CameraInfo topic; intrinsics missing "
                                 "(give --fx --fy --cx --cy)")
        topic = ([t for t in topics if "depth" in t] or topics)[0]
        msg = rec.first_message(topic)
        if msg is None:
            raise RecordingError(f"{path}: topic {topic} has no messages; intrinsics missing")
        K, w, h = camera_info_K(msg, f"{path}: {topic}")
    return dict(fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]), cy=float(K[1, 2]), width=w, height=h)
