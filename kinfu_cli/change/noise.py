"""How far apart two fusions of one unchanged surface may lie because of depth noise, per voxel.

A depth camera's error grows with distance: for a Kinect v1 (and structured-light / stereo sensors like it)
the axial noise is sigma(z) = 1.2 mm + 1.9 mm (z - 0.4 m)^2 (Nguyen, Izadi & Lovell 2012), about 1.4 cm at
3 m, where the disparity steps are ~2 cm as well. A fixed margin of one voxel, meant for pose noise, lets such a
surface jitter through as removed / added slabs several voxels thick (7-Scenes kitchen, two halves of one
static scan: 85 regions up to 614 cm^3, all 2.5-3.1 m from the cameras). So a changed voxel must lie
`sigmas` standard deviations of the difference of the two surface estimates, sqrt(sigma_b^2 + sigma_a^2),
away from every surface of the other volume, sigma_* taken at the voxel's distance from the nearest camera of
each fusion. The nearest camera gives a lower bound on the distance the voxel was seen from, hence on the
noise: the margin never exceeds what the sensor model asks for.

The model is a Kinect v1's; other sensors' noise grows otherwise (a RealSense D400's RMS error is distance^2 x
subpixel / (focal length x baseline), Intel's depth tuning guide, but the baseline is not in a volume), so a
volume whose camera is evidently not Kinect-like (a RealSense SDK recording's depth units, a depth image that is
not 4:3, a RealSense driver's topic names) is named in a warning rather than given an invented model.

The volumes do not store camera positions: the `trajectory.tum` that `kinfu fuse` writes beside its
volume.npz / ternary.npz is read when present; with one trajectory it stands for both; with none the fixed
margin alone applies (and changes.json says so).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import TrajectoryError
from kinfu_cli.io.tum import read_tum

#: Kinect v1 axial noise model sigma(z) = A + B (z - Z0)^2, metres (Nguyen et al. 2012).
SIGMA_A, SIGMA_B, SIGMA_Z0 = 0.0012, 0.0019, 0.4
#: Default margin in standard deviations of the two surfaces' difference: two (a two-sided 95 % band). Chosen
#: a priori, not fitted; on the kitchen halves 1.5 still leaves 2 regions (<= 41 voxels), 2 leaves none.
NOISE_SIGMAS = 2.0
#: Largest margin the noise may ask for, voxels (a far wall at 8 m with 5 mm voxels asks for ~50 voxels).
MAX_NOISE_MARGIN = 24
MODEL = "kinect-v1: sigma(z) = 1.2 mm + 1.9 mm (z - 0.4 m)^2, z = distance to the nearest camera"


# topics only a RealSense driver names so (realsense2_camera; its SDK bags say so by their depth units)
_REALSENSE_TOPICS = ("realsense", "aligned_depth_to_color", "image_rect_raw", "/device_0/sensor_")


def sensor_evidence(intrinsics: dict | None, report: dict | None) -> dict:
    """Whether the depth camera a volume was fused from looks like a Kinect v1 (the noise model's sensor):
    {"kinect_like": True / False / None (nothing known), "evidence": what says so}, from the volume's intrinsics
    and the report.json of the `kinfu fuse` run that wrote it."""
    report = report if isinstance(report, dict) else {}
    frames = report.get("frames") if isinstance(report.get("frames"), dict) else {}
    units = frames.get("depth_units_m")
    if isinstance(units, (int, float)) and not isinstance(units, bool):
        return {"kinect_like": False, "evidence": f"a RealSense SDK recording (depth units {units:g} m)"}
    roles = report.get("roles") if isinstance(report.get("roles"), dict) else {}
    topic = roles.get("depth_topic")
    if isinstance(topic, str) and any(t in topic for t in _REALSENSE_TOPICS):
        return {"kinect_like": False, "evidence": f"depth topic {topic} (a RealSense driver's)"}
    if isinstance(intrinsics, dict) and intrinsics.get("width") and intrinsics.get("height"):
        w, h = int(intrinsics["width"]), int(intrinsics["height"])
        if abs(w / h - 4 / 3) > 0.02:
            return {"kinect_like": False, "evidence": f"depth images {w}x{h}, not the 4:3 of a Kinect v1"}
        return {"kinect_like": True, "evidence": f"depth images {w}x{h}, 4:3 like a Kinect v1's"}
    return {"kinect_like": None, "evidence": "no intrinsics recorded"}


def depth_sigma(distance: np.ndarray) -> np.ndarray:
    """Axial depth noise (m) at `distance` (m) from the camera."""
    z = np.maximum(np.asarray(distance, dtype=np.float64) - SIGMA_Z0, 0.0)
    return SIGMA_A + SIGMA_B * z * z


def read_cameras(volume_path: str | os.PathLike) -> tuple[np.ndarray | None, str | None]:
    """Camera positions (M, 3) of the fusion that wrote `volume_path`, from the trajectory.tum beside it; (None,
    None) when there is none, (None, reason) when it cannot be read."""
    path = Path(volume_path).parent / "trajectory.tum"
    if not path.is_file():
        return None, None
    try:
        _, poses = read_tum(path)
    except TrajectoryError as exc:
        return None, str(exc)
    if len(poses) == 0:
        return None, f"{path}: no pose"
    return poses[:, :3, 3].copy(), None


def nearest_distance(points: np.ndarray, cameras: np.ndarray) -> np.ndarray:
    """(N,) distance of each point to the nearest camera position."""
    return cKDTree(np.asarray(cameras, dtype=np.float64)).query(np.asarray(points, dtype=np.float64))[0]


def noise_margins(points: np.ndarray, cameras_before: np.ndarray, cameras_after: np.ndarray, sigmas: float,
                  voxel_size: float) -> np.ndarray:
    """(N,) margin in voxels each world point needs: sigmas x the noise of the two surfaces' difference."""
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    s = np.hypot(depth_sigma(nearest_distance(points, cameras_before)),
                 depth_sigma(nearest_distance(points, cameras_after)))
    return np.minimum(np.ceil(sigmas * s / voxel_size - 1e-9), MAX_NOISE_MARGIN).astype(np.int64)
