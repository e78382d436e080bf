"""The numpy replacements that keep open3d out of `kinfu segment` agree with open3d: voxel down-sampling (the same
points, bit for bit) and the support plane's RANSAC (the same plane; seeds no longer move it)."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from kinfu_cli.segmentation.plane_ransac import plane_from_points, ransac_plane
from kinfu_cli.segmentation.surface import SurfaceCloud, downsample


def _angle_deg(a, b) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(np.dot(a, b)) / np.linalg.norm(a) / np.linalg.norm(b))))))


def _table_with_objects(seed: int = 0, n: int = 20000) -> np.ndarray:
    """A slightly tilted 1 x 1 m table (2 mm noise) holding 40 % clutter above it."""
    rng = np.random.default_rng(seed)
    m = int(0.6 * n)
    xy = rng.uniform(-0.5, 0.5, (m, 2))
    table = np.column_stack([xy, 0.7 + 0.02 * xy[:, 0] + rng.normal(0, 0.002, m)])
    clutter = rng.uniform([-0.5, -0.5, 0.72], [0.5, 0.5, 1.0], (n - m, 3))
    return np.vstack([table, clutter])


def test_downsample_gives_open3d_voxel_down_sample_points_bit_for_bit():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.3, 0.4, (5000, 3))
    nrm = rng.normal(size=(5000, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    ours = downsample(SurfaceCloud(pts, nrm), 0.05)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pc.normals = o3d.utility.Vector3dVector(nrm)
    ref = pc.voxel_down_sample(0.05)
    rp, rn = np.asarray(ref.points), np.asarray(ref.normals)
    rn = rn / np.linalg.norm(rn, axis=1, keepdims=True)
    a, b = np.lexsort(ours.points.T[::-1]), np.lexsort(rp.T[::-1])
    assert len(ours) == len(rp) > 100
    assert np.array_equal(ours.points[a], rp[b])
    assert np.abs(ours.normals[a] - rn[b]).max() < 1e-12
    # grid-index order: the same cloud shuffled gives the same voxels in the same order (sums in another order)
    perm = rng.permutation(len(pts))
    again = downsample(SurfaceCloud(pts[perm], nrm[perm]), 0.05)
    assert np.abs(again.points - ours.points).max() < 1e-15


def test_ransac_plane_finds_the_table_as_open3d_does_and_seeds_agree():
    pts = _table_with_objects()
    true_n = np.array([-0.02, 0.0, 1.0]) / np.linalg.norm([-0.02, 0.0, 1.0])
    planes = []
    for seed in range(4):
        plane, inl = ransac_plane(pts, 0.01, 1000, np.random.default_rng(seed))
        assert abs(np.linalg.norm(plane[:3]) - 1) < 1e-12
        assert _angle_deg(plane[:3], true_n) < 0.5
        assert abs(np.sum(np.abs(pts[:12000] @ plane[:3] + plane[3]) < 0.01) - 12000) < 150  # the table's points
        assert len(inl) >= 11800 and np.all(np.abs(pts[inl] @ plane[:3] + plane[3]) < 0.01)
        planes.append(plane * np.sign(plane[2]))
    assert np.ptp(np.array(planes), axis=0).max() < 1e-9  # polished: the winning triple no longer matters
    o3d.utility.random.seed(0)
    model, _ = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)).segment_plane(0.01, 3, 1000)
    model = np.asarray(model) * np.sign(model[2])
    assert _angle_deg(model[:3], planes[0][:3]) < 0.5 and abs(model[3] - planes[0][3]) < 0.003
    # the same seed, the same answer
    again, inl_again = ransac_plane(pts, 0.01, 1000, np.random.default_rng(0))
    assert np.array_equal(again * np.sign(again[2]), planes[0]) and len(inl_again) == len(
        ransac_plane(pts, 0.01, 1000, np.random.default_rng(0))[1])


def test_plane_from_points_is_the_least_squares_plane_and_degenerate_input_gives_zeros():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-1, 1, (500, 2))
    pts = np.column_stack([xy, 0.3 * xy[:, 1] - 0.1])  # z = 0.3 y - 0.1, exactly
    plane = plane_from_points(pts)
    assert np.abs(pts @ plane[:3] + plane[3]).max() < 1e-12
    assert not plane_from_points(np.zeros((0, 3))).any()
    assert not plane_from_points(np.tile([1.0, 2.0, 3.0], (5, 1))).any()
    plane, inl = ransac_plane(np.tile([1.0, 2.0, 3.0], (50, 1)), 0.01, 100, np.random.default_rng(0))
    assert not plane.any() and len(inl) == 0
