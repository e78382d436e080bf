"""Rigid poses: the one look-at construction, quaternion conversions (scipy) and rigidity checks.

Poses are 4x4 camera-to-world unless a name says otherwise (`T_a_b` maps frame b into a); cameras use
the optical frame (x right, y down, z forward). Quaternions are (x, y, z, w), as ROS writes them.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.core.errors import ConfigError, TransformError, VolumeError
from kinfu_cli.core.volume_file import MAX_COORDINATE_M


def look_at(position, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """4x4 camera-to-world pose at `position` looking at `target` with the image y axis pointing
    away from `up` (upright image); a pose looking straight along `up` uses the world x axis
    (the y axis when it looks along x)."""
    p = np.asarray(position, dtype=np.float64).reshape(3)
    z = np.asarray(target, dtype=np.float64).reshape(3) - p
    n = np.linalg.norm(z)
    if not n > 0:
        raise ConfigError("position and target coincide", parameter="target")
    z /= n
    up = np.asarray(up, dtype=np.float64)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, p
    return T


def matrix_to_quaternion(R) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions (x, y, z, w) with w >= 0."""
    R = np.asarray(R, dtype=np.float64)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()
    q[q[:, 3] < 0] *= -1
    return q.reshape(R.shape[:-2] + (4,))


def quaternion_to_matrix(q) -> np.ndarray:
    """(..., 4) quaternions (x, y, z, w), normalised here -> (..., 3, 3) rotations; TransformError for a
    quaternion of zero or non-finite norm."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1)
    if not np.all(np.isfinite(n)) or np.any(n < 1e-12):
        bad = q.reshape(-1, 4)[int(np.flatnonzero(~(np.isfinite(n) & (n >= 1e-12)).ravel())[0])]
        raise TransformError(f"quaternion {bad.tolist()} has zero or non-finite norm")
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))


def check_rigid(T: np.ndarray, what: str = "T_world_camera") -> np.ndarray:
    """Return T as float64 (4, 4) or raise VolumeError when it is not a finite rigid transform."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise VolumeError(f"{what}: expected a 4x4 pose, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise VolumeError(f"{what}: pose is not finite (NaN or inf)")
    R = T[:3, :3]
    if (np.abs(R.T @ R - np.eye(3)).max() > 1e-3 or abs(np.linalg.det(R) - 1.0) > 1e-3
            or np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9):
        raise VolumeError(f"{what}: pose is not rigid (rotation not orthonormal with det +1, or last row "
                          f"not [0 0 0 1])")
    return T


def check_poses(poses, source: str = "poses") -> np.ndarray:
    """Validate (N, 4, 4) rigid camera-to-world poses; raises ConfigError naming `source`."""
    arr = np.asarray(poses, dtype=np.float64)
    if arr.ndim == 2 and arr.shape == (4, 4):
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise ConfigError(f"{source}: expected a list of 4x4 poses, got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ConfigError(f"{source}: no poses")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr).all(axis=(1, 2)))[0])
        raise ConfigError(f"{source}: pose {bad} is not finite")
    far = np.flatnonzero(np.abs(arr[:, :3, 3]).max(axis=1) > MAX_COORDINATE_M)
    if far.size:  # 1e300 overflowed the ray casts' voxel indices (numpy warnings)
        raise ConfigError(f"{source}: pose {int(far[0])} is more than {MAX_COORDINATE_M:g} m from the origin")
    R = arr[:, :3, :3]
    err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = np.flatnonzero((err > 1e-4) | (det < 0) | np.any(np.abs(arr[:, 3] - [0, 0, 0, 1]) > 1e-9, axis=1))
    if bad.size:
        raise ConfigError(f"{source}: pose {int(bad[0])} is not a rigid transform (rotation not orthonormal "
                          "or last row not [0 0 0 1])")
    return arr


def plane_axes(normal: np.ndarray) -> np.ndarray:
    """(2, 3) two orthonormal vectors spanning the plane of unit `normal` (right-handed with it)."""
    n = np.asarray(normal, dtype=np.float64)
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    return np.stack([a, np.cross(n, a)])
