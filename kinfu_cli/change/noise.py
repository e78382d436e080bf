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
