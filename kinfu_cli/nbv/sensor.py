"""The NBV sensor model a run uses: explicit intrinsics, a recording's CameraInfo, the intrinsics the volume was
fused with, or (none of them) the Kinect v1 preset."""

from __future__ import annotations

import os

from kinfu_cli.core.camera import SENSOR_PRESETS, CameraModel
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.camera_info import intrinsics_from_recording


def camera_from_options(fx: float | None = None, fy: float | None = None, cx: float | None = None,
                        cy: float | None = None, width: int | None = None, height: int | None = None,
                        camera_info: str | os.PathLike | None = None, min_range: float = 0.5,
                        max_range: float = 4.0, vfov_extra_deg: float = 0.0,
                        recorded: dict | None = None) -> CameraModel:
    """Build the NBV sensor model from explicit intrinsics, a recording, the volume's, or the default preset.

    Either all of fx, fy, cx, cy (width/height default 640x480), or `camera_info` (a recording with a
    sensor_msgs/CameraInfo topic), or none of them: then `recorded` (fx, fy, cx, cy, width, height: the
    camera the volume was fused with, `fusion.volume.volume_intrinsics`), else the Kinect v1 calibration the
    paper used (`camera_source` says which).
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
        intr = dict(SENSOR_PRESETS["kinect_v1"] if recorded is None else recorded)
        if width is not None or height is not None:
            raise ConfigError("an image size needs fx, fy, cx, cy (or camera_info) as well", parameter="width/height")
    return CameraModel(float(intr["fx"]), float(intr["fy"]), float(intr["cx"]), float(intr["cy"]),
                       int(intr["width"]), int(intr["height"]), float(min_range), float(max_range),
                       float(vfov_extra_deg))


def camera_source(fx=None, fy=None, cx=None, cy=None, camera_info=None, recorded: dict | None = None) -> str:
    """Where `camera_from_options` takes the intrinsics from: "intrinsics" (given), "camera_info", "volume"
    (recorded at fusion) or "kinect_v1 preset"."""
    if camera_info is not None:
        return "camera_info"
    if any(v is not None for v in (fx, fy, cx, cy)):
        return "intrinsics"
    return "volume" if recorded is not None else "kinect_v1 preset"


def preset_warning() -> str:
    """The warning of a run that falls back to the Kinect v1 preset."""
    p = SENSOR_PRESETS["kinect_v1"]
    return (f"the volume does not record the camera it was fused with (a ternary.npz, or fused before kinfu "
            f"stored intrinsics): ranking with the Kinect v1 preset fx = fy = {p['fx']:g}, cx = {p['cx']:g}, "
            f"cy = {p['cy']:g}, {p['width']}x{p['height']}; give the sensor's intrinsics or a CameraInfo recording")
