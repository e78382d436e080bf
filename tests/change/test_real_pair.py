"""A real before/after pair: rgbd-tabletop-box frames fused as they are (before), and other frames of the same
sequence with the cracker box on the desk edited out (after): its pixels show the desk plane behind it, as if
it had been taken away. The diff must find that removal and little else (sensor noise of two different frame
sets, no pose noise added: the poses are the data set's)."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.change.diff import diff_grids

# where the cracker box stands, in the first camera's frame (x right, y down, z forward), read off frame 15
BOX_LO, BOX_HI = np.array([0.19, -0.12, 0.57]), np.array([0.36, 0.0, 0.72])
OBJECT_CENTRE = np.array([0.27, -0.04, 0.63])


def _frames(folder, numbers):
    import cv2

    from kinfu_cli.fusion import filters

    for i in numbers:
        d = cv2.imread(str(folder / f"frame-{i:06d}.depth.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
        yield filters.fill_gaps(filters.range_filter(d, 0.1, 1.5), 2)[0], np.loadtxt(folder / f"frame-{i:06d}.pose.txt")


def _volume():
    from kinfu_cli.fusion.volume import TernaryVolume

    return TernaryVolume(size=(1.1, 0.8, 1.0), voxel_size=0.01, origin=(-0.5, -0.4, 0.1), truncation=0.03,
                         min_depth=0.1, max_depth=1.5, color=False)


def _without_object(depth, K, T, plane):
    """Depth with the object's pixels replaced by the plane behind them (no reading where the plane is not
    within 0.3 m behind the object); the number of pixels edited."""
    n, d0 = plane
    v, u = np.mgrid[0:depth.shape[0], 0:depth.shape[1]]
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(depth)], axis=-1)
    world = (rays * depth[..., None]) @ T[:3, :3].T + T[:3, 3]
    inside = np.all((world >= BOX_LO) & (world <= BOX_HI), axis=-1) & (world @ n + d0 < -0.01) & (depth > 0)
    along = -(T[:3, 3] @ n + d0) / ((rays @ T[:3, :3].T) @ n)  # depth at which each ray meets the plane
    behind = inside & (along > depth) & (along < depth + 0.3)
    out = depth.copy()
    out[inside] = 0.0
    out[behind] = along[behind]
    return out, int(inside.sum())


@pytest.mark.slow
@pytest.mark.shared_data
def test_object_edited_out_of_real_frames_is_found_removed_and_little_else(shared_data):
    import open3d as o3d

    folder = shared_data("rgbd-tabletop-box")
    K = np.loadtxt(folder / "intrinsics.K.txt")
    before = _volume()
    for depth, T in _frames(folder, range(15, 57, 8)):
        before.integrate(depth, K, T)
    grid = before.ternary_grid()
    o3d.utility.random.seed(0)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(grid.centers(np.argwhere(grid.labels == 1))))
    model, _ = cloud.segment_plane(0.01, 3, 300)
    n, d0 = np.array(model[:3]), float(model[3])
    if n[1] < 0:  # orient the desk's normal down (+y in a camera frame): above the desk is n.p + d0 < 0
        n, d0 = -n, -d0
    after, unchanged = _volume(), _volume()
    edited = 0
    for depth, T in _frames(folder, range(19, 61, 8)):  # other frames: other sensor noise
        unchanged.integrate(depth, K, T)
        depth, k = _without_object(depth, K, T, (n, d0))
        edited += k
        after.integrate(depth, K, T)
    assert edited > 10_000  # the object is in view
    control = diff_grids(grid, unchanged.ternary_grid())  # the same scene from other frames: nothing changed
    assert control.masks.raw["removed"] + control.masks.raw["added"] > 300  # noise the cleaning has to remove
    assert control.regions == [] and not control.warnings
    r = diff_grids(grid, after.ternary_grid())
    removed = [x for x in r.regions if x.kind == "removed"]
    assert len(removed) >= 1
    main = max(r.regions, key=lambda x: len(x.points))
    assert main.kind == "removed" and np.linalg.norm(main.centroid - OBJECT_CENTRE) < 0.05, main.centroid
    assert np.all(main.points >= BOX_LO - 0.01) and np.all(main.points <= BOX_HI + 0.01)
    others = sum(len(x.points) for x in r.regions if x is not main)
    assert others <= 0.25 * len(main.points), [(x.kind, len(x.points), x.centroid) for x in r.regions]
    assert not r.warnings
