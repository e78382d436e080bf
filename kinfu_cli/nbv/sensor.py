"""The NBV sensor model a run uses: explicit intrinsics, a recording's CameraInfo, the intrinsics the volume was
fused with, or (none of them) the Kinect v1 preset."""

from __future__ import annotations

import math
import os

from kinfu_cli.core.camera import SENSOR_PRESETS, CameraModel, field_of_view_problem
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.camera_info import intrinsics_from_recording

# Most pixels an NBV sensor image may hold: 4096 x 4096, ~55 x the Kinect v1's 640 x 480 and above any depth
# camera's. Casting grows with the pixels: 16 x the Kinect's took ~12 s more per POI at the paper's sphere (peak
# memory 0.45 -> 0.65 GB), so this bound is ~45 s a POI; a 1e9 px wide image ran out of memory.
MAX_IMAGE_PIXELS = 4096 * 4096
# Most pixels the image the rays are cast from may hold: the sensor image grown by vfov_extra_deg above and below
# (CameraModel.widened) adds fy tan(vfov_extra_deg) rows on either side, whatever the height: a 100000 x 2 px image
# at fy = 50000 becomes 100000 x 8752 px (875 M) and ran out of memory. Twice MAX_IMAGE_PIXELS lets a 4096 x 4096
# sensor widen at any vertical field of view over about twice vfov_extra_deg (cast whole, ~80 B a pixel: 4096 x 4952
# px took 1.6 GB).
MAX_CAST_PIXELS = 2 * MAX_IMAGE_PIXELS
# How far outside the image the principal point may lie, as a share of the image's width (height): a calibrated
# camera has it near the centre, a cropped image or a shifted lens off it, even past an edge, so half an image of
# margin on either side; farther out the optical axis misses the image and the views look past the POI they aim at
# (cy = 5000 px in a 480 px image at fy = 525 tilts them by 83 deg) and see nothing.
PRINCIPAL_POINT_MARGIN = 0.5


def camera_from_options(fx: float | None = None, fy: float | None = None, cx: float | None = None,
                        cy: float | None = None, width: int | None = None, height: int | None = None,
                        camera_info: str | os.PathLike | None = None, min_range: float = 0.5,
                        max_range: float = 4.0, vfov_extra_deg: float = 0.0,
                        recorded: dict | None = None, recorded_from: str = "the volume") -> CameraModel:
    """Build the NBV sensor model from explicit intrinsics, a recording, the volume's, or the default preset.

    Either all of fx, fy, cx, cy (width/height default 640x480), or `camera_info` (a recording with a
    sensor_msgs/CameraInfo topic), or none of them: then `recorded` (fx, fy, cx, cy, width, height: the
    camera the volume was fused with, `fusion.volume.volume_intrinsics`; `recorded_from` names that volume in
    errors), else the Kinect v1 calibration the paper used (`camera_source` says which). An image over
    MAX_IMAGE_PIXELS (or over MAX_CAST_PIXELS once widened), focal lengths that cannot be in pixels, a field of
    view that `vfov_extra_deg` widens to 180 degrees or a principal point over PRINCIPAL_POINT_MARGIN images
    outside the image is a ConfigError naming where the intrinsics came from.
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
    cam = CameraModel(float(intr["fx"]), float(intr["fy"]), float(intr["cx"]), float(intr["cy"]),
                      int(intr["width"]), int(intr["height"]), float(min_range), float(max_range),
                      float(vfov_extra_deg))
    if camera_info is not None:
        source, parameter = f"{camera_info}: its CameraInfo's", "camera_info"
    elif given:
        source, parameter = "the given", None
    elif recorded is not None:
        source, parameter = f"{recorded_from}: the camera it was fused with, its", None
    else:
        source, parameter = "the Kinect v1 preset's", None
    _check_sensor(cam, source, parameter)
    return cam


def _check_sensor(cam: CameraModel, source: str, parameter: str | None) -> None:
    """Refuse a sensor image too large to cast, with an impossible field of view or with its principal point far
    outside it, naming `source` (where the intrinsics came from; `parameter` the option that gave them, None:
    fx/fy/cx/cy/width/height themselves): otherwise a huge image runs out of memory, its widening blames
    vfov_extra_deg, which was not wrong, or the views see nothing and only a generic warning follows. The widened
    image (MAX_CAST_PIXELS) grows with fy, not the height: a few rows at a long focal length become thousands."""
    if cam.width * cam.height > MAX_IMAGE_PIXELS:
        side = math.isqrt(MAX_IMAGE_PIXELS)
        raise ConfigError(f"{source} image size {cam.width}x{cam.height} px holds {cam.width * cam.height:,} "
                          f"pixels, more than the {MAX_IMAGE_PIXELS:,} ({side}x{side}) an NBV sensor may have; "
                          f"expected a depth camera's image size", parameter=parameter or "width/height")
    if problem := field_of_view_problem(cam.K, cam.width, cam.height):
        raise ConfigError(f"{source} intrinsics: {problem}", parameter=parameter or "fx/fy/width/height")
    if cam.vfov_extra_deg > 0:
        top = math.degrees(math.atan((cam.cy + 0.5) / cam.fy))
        bottom = math.degrees(math.atan((cam.height - 0.5 - cam.cy) / cam.fy))
        if max(top, bottom) + cam.vfov_extra_deg >= 90:
            raise ConfigError(f"{source} fy={cam.fy:g}, cy={cam.cy:g}, height {cam.height} px see {top:.1f} deg "
                              f"above and {bottom:.1f} deg below the optical axis; {cam.vfov_extra_deg:g} deg more "
                              f"on each side (vfov_extra_deg) reach 180 degrees: expected a principal point inside "
                              f"the image and a depth camera's focal length in pixels",
                              parameter=parameter or "fy/cy/height")
    cast = cam.widened()
    if cast.width * cast.height > MAX_CAST_PIXELS:
        raise ConfigError(f"{source} {cam.width}x{cam.height} px image at fy={cam.fy:g}, widened by "
                          f"{cam.vfov_extra_deg:g} deg above and below (vfov_extra_deg), is cast as {cast.width}x"
                          f"{cast.height} px: {cast.width * cast.height:,} pixels, more than the {MAX_CAST_PIXELS:,} "
                          f"an NBV sensor may cast; expected a depth camera's image (tens of degrees tall, not a "
                          f"few rows) or a smaller vfov_extra_deg",
                          parameter=parameter or "fy/height/vfov_extra_deg")
    outside = [f"{name}={value:g} is outside [{-PRINCIPAL_POINT_MARGIN * size:g}, "
               f"{(1 + PRINCIPAL_POINT_MARGIN) * size:g}] for a {side} of {size} px"
               for name, value, size, side in (("cx", cam.cx, cam.width, "width"), ("cy", cam.cy, cam.height, "height"))
               if not -PRINCIPAL_POINT_MARGIN * size <= value <= (1 + PRINCIPAL_POINT_MARGIN) * size]
    if outside:
        raise ConfigError(f"{source} principal point {', '.join(outside)}: the views would look past the POI they "
                          f"aim at and see nothing; expected a principal point within half an image of the image "
                          f"(near its centre)", parameter=parameter or "cx/cy")


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
