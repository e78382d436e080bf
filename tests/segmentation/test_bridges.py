"""Bridges across unknown space (segmentation.bridges): a face cut by a band of missing depth is one segment, two
boxes with observed free space between them stay two. Single simulated views fused into a ternary volume."""

from dataclasses import replace

import numpy as np
import pytest

from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN
from kinfu_cli.core.poses import look_at
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.segmentation.bridges import space_query
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume
from kinfu_cli.sim.scene import Scene, Table, resting_object
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

W, H = 320, 240
RED = (0.8, 0.2, 0.1)


def _segments(objects, band_px: int, bridge_gap: float) -> int:
    """Object segments of one fused view; band_px: a vertical band of the objects' pixels through the image
    centre has no depth (a glossy or dark stripe)."""
    table = Table(center=(0.0, 0.0), size=(1.2, 1.2), top_z=0.0, thickness=0.02, leg_width=0.0)
    scene = Scene(table, tuple(objects), False, 0)
    K = kinect_v1_intrinsics(W, H)
    T = look_at((0.0, -0.75, 0.55), (0.0, 0.0, 0.07))
    f = DepthSensor(K, W, H, seed=0).render_frame(scene, T, frame_seed=0)
    depth = f.depth.copy()
    c0 = W // 2 - band_px // 2
    band = depth[:, c0:c0 + band_px]
    band[f.labels[:, c0:c0 + band_px] >= 3] = 0.0
    vol = TernaryVolume(size=1.0, resolution=200, origin=(-0.5, -0.5, -0.3), color=True)
    vol.integrate(depth, K, T, f.color)
    o = SegmentOptions(superquadrics=False)
    res = analyse_volume(vol, replace(o, segmentation=replace(o.segmentation, up=None, bridge_gap=bridge_gap)))
    return len([s for s in np.unique(res.segmentation.labels) if s > 0])


@pytest.mark.parametrize("band_px", [6, 10])
def test_a_box_face_cut_by_a_band_of_missing_depth_is_one_segment(band_px):
    box = resting_object("box", "box", {"x": 0.2, "y": 0.1, "z": 0.15}, colour=RED)
    assert _segments([box], band_px, 0.0) == 2  # without the bridge the band splits it
    assert _segments([box], band_px, 0.05) == 1


def test_two_boxes_with_observed_free_space_between_stay_two():
    a = resting_object("a", "box", {"x": 0.09, "y": 0.1, "z": 0.15}, xy=(-0.065, 0.0), colour=RED)
    b = resting_object("b", "box", {"x": 0.09, "y": 0.1, "z": 0.15}, xy=(0.065, 0.0), colour=RED)
    assert _segments([a, b], 0, 0.05) == 2


def test_space_query_reads_labels_and_calls_outside_unknown():
    labels = np.full((4, 4, 4), UNKNOWN, np.int8)
    labels[1, 2, 3] = EMPTY
    labels[0, 0, 0] = OCCUPIED
    q, vs = space_query(labels, (1.0, 0.0, 0.0), 0.5)
    pts = np.array([[1.0 + 0.75, 1.25, 1.75], [1.1, 0.1, 0.1], [0.0, 0.0, 0.0], [3.1, 0.0, 0.0]])
    assert vs == 0.5 and q(pts).tolist() == [EMPTY, OCCUPIED, UNKNOWN, UNKNOWN]


def test_volume_space_reads_the_blocks_as_the_dense_labels_do():
    table = Table(center=(0.0, 0.0), size=(1.2, 1.2), top_z=0.0, thickness=0.02, leg_width=0.0)
    box = resting_object("box", "box", {"x": 0.2, "y": 0.1, "z": 0.15}, colour=RED)
    K = kinect_v1_intrinsics(W, H)
    T = look_at((0.0, -0.75, 0.55), (0.0, 0.0, 0.07))
    f = DepthSensor(K, W, H, seed=0).render_frame(Scene(table, (box,), False, 0), T, frame_seed=0)
    vol = TernaryVolume(size=1.0, resolution=200, origin=(-0.5, -0.5, -0.3), color=True)
    vol.integrate(f.depth, K, T, f.color)
    dense = vol.labels()
    pts = np.random.default_rng(0).uniform(-0.6, 0.8, (20000, 3))
    from kinfu_cli.segmentation.bridges import volume_space
    got = volume_space(vol)[0](pts)
    want = space_query(dense, vol.origin, vol.voxel_size)[0](pts)
    assert np.array_equal(got, want) and len(set(want.tolist())) == 3
