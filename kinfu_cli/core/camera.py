"""Pinhole camera models and the named sensor presets every stage uses.

`CameraModel` is the NBV sensor model: pinhole intrinsics, image size, range limits, optional wider
vertical field of view.

Camera frame is the optical frame (x right, y down, z forward). The paper tilts the sensor by
+-5 degrees about its horizontal axis at every viewpoint, so its NBV sensor model has a wider vertical
field of view; `vfov_extra_deg` adds that many degrees above and below by growing the image height at
the same focal length (`CameraModel.widened()`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from kinfu_cli.core.errors import ConfigError

# Named sensor presets at their native image size. The paper's sensor is a Kinect v1, which has two
# cameras: "kinect_v1" is the depth image registered to the colour camera (fx = 525, the openni_launch
# default that ROS recordings carry and the NBV sensor model assumes); "kinect_v1_ir" is the raw IR
# (depth) camera, fx = 585, whose disparity geometry the simulated sensor reproduces.
SENSOR_PRESETS = {
    "kinect_v1": dict(fx=525.0, fy=525.0, cx=319.5, cy=239.5, width=640, height=480),
    "kinect_v1_ir": dict(fx=585.0, fy=585.0, cx=319.5, cy=239.5, width=640, height=480),
}
KINECT_V1 = SENSOR_PRESETS["kinect_v1"]


# the widest field of view taken for a depth camera's pinhole intrinsics (depth cameras see 55-90 degrees, wide
# ones up to ~120): wider means focal lengths in other units than pixels (normalised by the image size, or mm)
MAX_FIELD_OF_VIEW_DEG = 170.0
# the narrowest: a depth camera sees tens of degrees even cropped to a small region; under half a degree the focal
# lengths are not in pixels either (or a placeholder such as 1e9)
MIN_FIELD_OF_VIEW_DEG = 0.5


def field_of_view_problem(K: np.ndarray, width: int, height: int) -> str | None:
    """Why K cannot hold a depth camera's focal lengths in pixels for width x height images (a field of view over
    MAX_FIELD_OF_VIEW_DEG or under MIN_FIELD_OF_VIEW_DEG), or None (also when the size is unknown)."""
    if width <= 0 or height <= 0:
        return None
    fx, fy = float(K[0, 0]), float(K[1, 1])
    fov = max(2 * math.degrees(math.atan2(width / 2, fx)), 2 * math.degrees(math.atan2(height / 2, fy)))
    if fov > MAX_FIELD_OF_VIEW_DEG:
        return (f"fx={fx:.3g}, fy={fy:.3g} give a {fov:.1f} deg field of view over {width}x{height} px images (over "
                f"{MAX_FIELD_OF_VIEW_DEG:.0f}: expected focal lengths in pixels)")
    if fov < MIN_FIELD_OF_VIEW_DEG:  # both ways: a sensor of a few rows may be narrow across them
        return (f"fx={fx:.3g}, fy={fy:.3g} give a {fov:.2g} deg field of view over {width}x{height} px images "
                f"(under {MIN_FIELD_OF_VIEW_DEG:g}: expected focal lengths in pixels)")
    return None


def intrinsics_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """3x3 pinhole matrix K."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)


def preset_intrinsics(name: str, width: int | None = None, height: int | None = None) -> np.ndarray:
    """K of a named preset, scaled to width x height (focal lengths scale per axis, principal point at the
    image centre); raises ConfigError for an unknown name or an image smaller than 2x2."""
    if name not in SENSOR_PRESETS:
        raise ConfigError(f"sensor preset {name!r}: expected one of {', '.join(SENSOR_PRESETS)}")
    p = SENSOR_PRESETS[name]
    width = p["width"] if width is None else int(width)
    height = p["height"] if height is None else int(height)
    if width < 2 or height < 2:
        raise ConfigError(f"image size {width}x{height}: expected at least 2x2 pixels")
    return intrinsics_matrix(p["fx"] * width / p["width"], p["fy"] * height / p["height"], (width - 1) / 2.0,
                             (height - 1) / 2.0)


def scaled_intrinsics(K: np.ndarray, factor: float | tuple[float, float]) -> np.ndarray:
    """Intrinsics of the image resized by `factor` (or (x factor, y factor)), pixel centres preserved."""
    fx_, fy_ = (factor, factor) if np.isscalar(factor) else factor
    Ks = np.asarray(K, dtype=np.float64).copy()
    Ks[0, 0] *= fx_
    Ks[1, 1] *= fy_
    Ks[0, 2] = (Ks[0, 2] + 0.5) * fx_ - 0.5
    Ks[1, 2] = (Ks[1, 2] + 0.5) * fy_ - 0.5
    return Ks


# a resized image (image_proc's resize, a decimation filter) keeps its aspect ratio to within rounding
RESIZE_ASPECT_TOLERANCE = 0.01


def is_resized(size: tuple[int, int], of: tuple[int, int]) -> bool:
    """Whether an image of `size` (width, height) can be one of `of` resized: the same aspect ratio, to within
    RESIZE_ASPECT_TOLERANCE of the scale (another aspect ratio is another camera's pixels)."""
    if min(of) <= 0 or min(size) <= 0:
        return False
    sx, sy = size[0] / of[0], size[1] / of[1]
    return abs(sx - sy) <= RESIZE_ASPECT_TOLERANCE * max(sx, sy)


def parse_intrinsics(value) -> tuple[float, float, float, float] | None:
    """'fx,fy,cx,cy' (or 4 numbers) -> tuple, None for None; ConfigError naming the intrinsics parameter for
    anything but finite numbers with positive focal lengths."""
    if value is None:
        return None
    try:
        vals = tuple(float(v) for v in (value.split(",") if isinstance(value, str) else value))
    except (TypeError, ValueError):
        vals = ()
    if len(vals) != 4 or not all(np.isfinite(vals)) or vals[0] <= 0 or vals[1] <= 0:
        raise ConfigError(f"expected fx,fy,cx,cy (finite numbers, positive focal lengths), got {value!r}",
                          parameter="intrinsics")
    return vals  # type: ignore[return-value]


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
                raise ConfigError(f"expected a positive focal length in pixels, got {v}", parameter=name)
        for name in ("cx", "cy"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"expected a finite principal point, got {getattr(self, name)}", parameter=name)
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ConfigError(f"expected a positive image size, got {self.width}x{self.height}",
                              parameter="width/height")
        if not (0 <= self.min_range < self.max_range) or not math.isfinite(self.max_range):
            raise ConfigError(f"expected 0 <= min < max, got {self.min_range}, {self.max_range}",
                              parameter="min_range/max_range")
        if not (0 <= self.vfov_extra_deg < 45):
            raise ConfigError(f"expected 0 to 45 degrees, got {self.vfov_extra_deg}", parameter="vfov_extra_deg")

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
            raise ConfigError("the widened vertical field of view reaches 180 degrees", parameter="vfov_extra_deg")
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
