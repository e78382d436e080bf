"""The two baselines of `kinfu eval localize`, run on the same measurements as the MUPF.

- Scaling Series (Petrovskaya et al., the thesis' competitor, described in ch. 2 / 4.4.3): Bayesian Monte
  Carlo with annealing; each of the levels draws M poses uniformly in the delta-neighbourhood of every
  surviving particle (delta shrinks by zoom = 2^(-1/6) per level, so the neighbourhood volume halves), weighs
  them by the likelihood annealed with tau = (delta / delta*)^2 and prunes by importance resampling
  (duplicates removed). The particle count is therefore set by the posterior's shape; it is capped
  (`max_particles`), as an unlucky tuning otherwise grows it exponentially. Points only (no normals), as
  the thesis ran it on the MUPF's measurements.
- open3d RANSAC global registration on FPFH features followed by point-to-plane ICP: what a user would try
  today, registering the measurements onto 1000 points sampled on the mesh (as the thesis' ICP).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.localization.mesh_model import EULER, MeshModel, matrix_pose


@dataclass
class BaselineResult:
    """pose vector (model to world), I_L (m), seconds, and particles evaluated (Scaling Series)."""

    pose: np.ndarray
    index: float
    seconds: float
    evaluated: int = 0
    capped: bool = False


def _rigid(T: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(T)) and np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6)
                and np.linalg.det(T[:3, :3]) > 0 and np.abs(T[:3, 3]).max() < 1e3)


def _ball(rng: np.random.Generator, n: int, radius: float) -> np.ndarray:
    v = rng.standard_normal((n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v * (radius * rng.random(n) ** (1 / 3))[:, None]


def localize_scaling_series(model: MeshModel, points: np.ndarray, *, x0: np.ndarray | None = None,
                            delta0: float = 0.4, delta_star: float = 0.005, per_region: int = 8,
                            sigma: float = 0.01, max_particles: int = 1000, seed: int | None = 0
                            ) -> BaselineResult:
    """Scaling Series over poses within delta0 (m) of x0, rotations up to a half turn; the rotation distance is
    measured as arc length on the model's bounding sphere (angle x half diameter)."""
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    x0 = np.zeros(6) if x0 is None else np.asarray(x0, dtype=float)
    radius = model.diameter / 2
    zoom = 2.0 ** (-1.0 / 6.0)
    levels = max(1, math.ceil(math.log(delta_star / delta0) / math.log(zoom)))
    pos = x0[None, :3].copy()
    rot = Rotation.from_euler(EULER, x0[None, 3:6])
    delta, evaluated, capped = delta0, 0, False
    for _ in range(levels):
        n = len(pos) * per_region
        new_pos = np.repeat(pos, per_region, axis=0) + _ball(rng, n, delta)
        turn = _ball(rng, n, min(delta / radius, math.pi))
        parents = Rotation.from_quat(rot.as_quat()[np.repeat(np.arange(len(rot)), per_region)])
        new_rot = Rotation.from_rotvec(turn) * parents
        delta *= zoom
        tau = (delta / delta_star) ** 2
        poses = np.concatenate([new_pos, new_rot.as_euler(EULER)], axis=1)
        d = model.world_distances(poses, points)
        evaluated += n
        log_w = -0.5 * (d * d).sum(1) / (sigma ** 2 * tau)
        w = np.exp(log_w - log_w.max())
        keep = np.unique(rng.choice(n, size=n, p=w / w.sum()))
        if len(keep) * per_region > max_particles:  # the explosion the thesis warns of: keep the best
            capped = True
            keep = keep[np.argsort(-log_w[keep])[: max_particles // per_region]]
        pos, rot = new_pos[keep], new_rot[keep]
    poses = np.concatenate([pos, rot.as_euler(EULER)], axis=1)
    d = model.world_distances(poses, points)
    best = poses[int(np.argmin((d * d).sum(1)))]
    return BaselineResult(best, model.performance_index(best, points), time.perf_counter() - start, evaluated, capped)


def localize_ransac_icp(model: MeshModel, points: np.ndarray, *, voxel: float = 0.01, seed: int | None = 0
                        ) -> BaselineResult:
    """open3d FPFH + RANSAC global registration of the measurements to 1000 mesh samples, refined by ICP."""
    import open3d as o3d

    start = time.perf_counter()
    if seed is not None:
        o3d.utility.random.seed(int(seed))
    reg = o3d.pipelines.registration
    rng = np.random.default_rng(seed)
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(model.sample_surface(1000, rng)))
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=float)))
    feats = []
    for pc in (source, target):
        pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=30))
        feats.append(reg.compute_fpfh_feature(pc, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)))
    dist = 2 * voxel
    level = o3d.utility.get_verbosity_level()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)  # its warnings would reach stdout
    try:
        ransac = reg.registration_ransac_based_on_feature_matching(
            source, target, feats[0], feats[1], True, dist, reg.TransformationEstimationPointToPoint(False), 3,
            [reg.CorrespondenceCheckerBasedOnDistance(dist)], reg.RANSACConvergenceCriteria(100000, 0.999))
        icp = reg.registration_icp(source, target, dist, ransac.transformation,
                                   reg.TransformationEstimationPointToPlane())
    finally:
        o3d.utility.set_verbosity_level(level)
    # ICP maps measurements (world) into the model frame; with few points (the box: 15) it can return a
    # degenerate matrix, then RANSAC's result, else the prior stands
    T = next((np.asarray(c) for c in (icp.transformation, ransac.transformation) if _rigid(np.asarray(c))), np.eye(4))
    T_world_model = np.linalg.inv(T)
    pose = matrix_pose(T_world_model)
    return BaselineResult(pose, model.performance_index(pose, points), time.perf_counter() - start)
