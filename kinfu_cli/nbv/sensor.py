"""The NBV sensor model a run uses: explicit intrinsics, a recording's CameraInfo, or the Kinect v1 preset."""

from __future__ import annotations

import os

from kinfu_cli.core.camera import SENSOR_PRESETS, CameraModel
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.camera_info import intrinsics_from_recording


def camera_from_options(fx: float | None = None, fy: float | None = None, cx: float | None = None,
                        cy: float | None = None, width: int | None = None, height: int | None = None,
                        camera_info: str | os.PathLike | None = None, min_range: float = 0.5,
                        max_range: float = 4.0, vfov_extra_deg: float = 0.0) -> CameraModel:
    """Build the NBV sensor model from explicit intrinsics, a recording, or the default preset.

    Either all of fx, fy, cx, cy (width/height default 640x480), or `camera_info` (a recording with a
    sensor_msgs/CameraInfo topic), or none of them: then the Kinect v1 calibration the paper used.
    """
    given = {k: v for k, v in dict(fx=fx, fy=fy, cx=cx, cy=cy).items() if v is not None}
    if camera_info is not None:
        if given:
            raise ConfigError("give either a recording or fx/fy/cx/cy, not both", parameter="camera_info")
        intr = intrinsics_from_recording(camera_info)
        if width is not None or height is not None:
            raise ConfigError("the image size comes from camera_info; do not give both", parameter="width/height")
    elif given:
        missing = [k for k in ("fx", "fy", "cx", "cy") if k not in given]
        if missing:
            raise ConfigError(f"intrinsics missing: {', '.join(missing)} (give all of fx, fy, cx, cy, "
                              "or a camera_info recording)")
        intr = dict(given, width=640 if width is None else width, height=480 if height is None else height)
    else:
        intr = dict(SENSOR_PRESETS["kinect_v1"])
        if width is not None or height is not None:
            raise ConfigError("an image size needs fx, fy, cx, cy (or camera_info) as well", parameter="width/height")
    return CameraModel(float(intr["fx"]), float(intr["fy"]), float(intr["cx"]), float(intr["cy"]),
                       int(intr["width"]), int(intr["height"]), float(min_range), float(max_range),
                       float(vfov_extra_deg))
