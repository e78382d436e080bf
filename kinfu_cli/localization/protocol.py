"""The thesis' simulation protocol (Table 4.2): per generated mesh, trials whose true pose differs from the
6-D null vector by 0.05-0.1 m along one axis and 45-90 deg about one axis, L surface points (Table 4.3)
with Gaussian noise in random order; errors against the true pose and success by the symmetric average
distance (ADD-S), which counts poses equivalent under an object symmetry as correct."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.localization.mesh_model import MeshModel, pose_matrix


@dataclass
class Trial:
    """One trial: the true pose (vector, 4x4) and the measurements (L, 3) in the world frame."""

    pose: np.ndarray
    matrix: np.ndarray
    points: np.ndarray


def make_trial(model: MeshModel, n_points: int, noise: float, rng: np.random.Generator) -> Trial:
    """A true pose of the Table 4.2 kind and n_points noisy surface points seen at that pose."""
    T = np.eye(4)
    T[rng.integers(3), 3] = rng.choice([-1, 1]) * rng.uniform(0.05, 0.1)
    axis = np.zeros(3)
    axis[rng.integers(3)] = 1.0
    T[:3, :3] = Rotation.from_rotvec(axis * np.deg2rad(rng.uniform(45, 90)) * rng.choice([-1, 1])).as_matrix()
    local = model.sample_surface(n_points, rng)
    pts = local @ T[:3, :3].T + T[:3, 3] + rng.normal(0.0, noise, (n_points, 3))
    pose = np.concatenate([T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_euler("ZYX")])
    return Trial(pose, T, pts)


def pose_errors(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(rotation error deg, translation error m) between two 4x4 transforms."""
    dR = estimate[:3, :3] @ truth[:3, :3].T
    return float(np.rad2deg(Rotation.from_matrix(dR).magnitude())), float(np.linalg.norm(estimate[:3, 3] - truth[:3, 3]))


def add_s(model: MeshModel, estimate: np.ndarray, truth: np.ndarray, samples: np.ndarray) -> float:
    """Mean distance from the model's surface samples at the true pose to the mesh surface at the estimated
    pose (m, exact BVH distances): zero for the true pose and for any pose the object's symmetry makes look
    the same."""
    world = samples @ truth[:3, :3].T + truth[:3, 3]
    return float(model.exact_distances((world - estimate[:3, 3]) @ estimate[:3, :3]).mean())


def estimate_matrix(pose: np.ndarray | None) -> np.ndarray | None:
    return None if pose is None else pose_matrix(pose)
