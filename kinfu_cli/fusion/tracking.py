"""Camera poses for fusion: the paper's hint modes (digest §1.5).

forced: the given pose (robot kinematics / TF), no tracking.
icp:    frame-to-model point-to-plane ICP (open3d), initialised with the previous estimate.
hint:   the same ICP, initialised with the given (TF) pose.
topic:  the pose from a PoseStamped/Odometry topic, no tracking (forced with another source).

Frame-to-model: the model is the volume ray cast from the initial pose (vertices + normals), the data
is the new depth image back-projected in the camera frame; ICP estimates T_world_camera directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.fusion.placement import backproject
from kinfu_cli.fusion.raycast import model_cloud

POSE_MODES = ("forced", "icp", "hint", "topic")


@dataclass
class TrackResult:
    T_world_camera: np.ndarray
    fitness: float
    rmse: float
    lost: bool
    reason: str = ""


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


class FrameToModelTracker:
    """Point-to-plane ICP of a depth image against the volume's ray-cast surface.

    max_distances: coarse-to-fine correspondence distances (m); iterations per level; stride: pixel step
    for the data cloud; voxel: down-sampling of the data cloud (m); min_fitness: below it the frame is
    lost (the initial pose is kept); max_jump_m / max_jump_deg: larger corrections than these from the
    initial pose are rejected as lost too (KinFu's ICP limits: 0.10 m, 20 deg).
    """

    def __init__(self, max_distances=(0.10, 0.05, 0.02), iterations=(10, 10, 8), stride: int = 2,
                 voxel: float = 0.01, min_fitness: float = 0.3, max_jump_m: float = 0.10,
                 max_jump_deg: float = 20.0, model_scale: float = 0.5, min_points: int = 300):
        if len(max_distances) != len(iterations):
            raise ConfigError("tracker: max_distances and iterations must have the same length")
        self.max_distances = tuple(float(x) for x in max_distances)
        self.iterations = tuple(int(x) for x in iterations)
        self.stride = int(stride)
        self.voxel = float(voxel)
        self.min_fitness = float(min_fitness)
        self.max_jump_m = float(max_jump_m)
        self.max_jump_deg = float(max_jump_deg)
        self.model_scale = float(model_scale)
        self.min_points = int(min_points)

    def track(self, volume, depth: np.ndarray, K: np.ndarray, T_init: np.ndarray) -> TrackResult:
        """ICP of `depth` (camera frame) against the volume's surface seen from T_init; T_init when lost."""
        import open3d as o3d  # heavy: only when tracking

        reg = o3d.pipelines.registration
        T_init = np.asarray(T_init, dtype=np.float64)
        h, w = depth.shape
        target = model_cloud(volume, K, w, h, T_init, scale=self.model_scale)
        if len(target.points) < self.min_points:
            return TrackResult(T_init.copy(), 0.0, float("nan"), True, "model surface not visible")
        pts = backproject(depth, K, np.eye(4), stride=self.stride, min_depth=volume.min_depth,
                          max_depth=volume.max_depth)
        if len(pts) < self.min_points:
            return TrackResult(T_init.copy(), 0.0, float("nan"), True, "too few depth points")
        source = o3d.geometry.PointCloud()
        source.points = o3d.utility.Vector3dVector(pts)
        if self.voxel > 0:
            source = source.voxel_down_sample(self.voxel)
        T = T_init.copy()
        est = reg.TransformationEstimationPointToPlane()
        res = None
        for dist, it in zip(self.max_distances, self.iterations):
            res = reg.registration_icp(source, target, dist, T, est, reg.ICPConvergenceCriteria(max_iteration=it))
            T = np.asarray(res.transformation).copy()
        fitness, rmse = float(res.fitness), float(res.inlier_rmse)
        delta = np.linalg.inv(T_init) @ T
        if fitness < self.min_fitness:
            return TrackResult(T_init.copy(), fitness, rmse, True, f"fitness {fitness:.2f} < {self.min_fitness}")
        if np.linalg.norm(delta[:3, 3]) > self.max_jump_m or _angle_deg(delta[:3, :3]) > self.max_jump_deg:
            return TrackResult(T_init.copy(), fitness, rmse, True, "correction larger than the ICP limits")
        return TrackResult(T, fitness, rmse, False)


def ate_rmse(estimated: list[np.ndarray], truth: list[np.ndarray]) -> float:
    """Absolute trajectory error (RMSE of camera positions, metres), both in the same world frame."""
    e = np.array([np.asarray(T)[:3, 3] for T in estimated])
    t = np.array([np.asarray(T)[:3, 3] for T in truth])
    return float(np.sqrt(np.mean(np.sum((e - t) ** 2, axis=1))))
