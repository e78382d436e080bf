"""Dark / glossy material dropouts of the simulated sensor (sim.materials): off by default, on they only remove
depth, dark pixels lose about the asked share in blobs, glossy cylinders lose a band where the normal bisects
the projector and camera directions."""

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.scene import Scene, Table, resting_object
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

W, H = 160, 120


def _view(colour):
    table = Table(center=(0.0, 0.0), size=(1.2, 1.2), top_z=0.0, thickness=0.02, leg_width=0.0)
    obj = resting_object("can", "cylinder", {"radius": 0.06, "height": 0.2}, colour=colour)
    box = resting_object("box", "box", {"x": 0.1, "y": 0.1, "z": 0.1}, xy=(0.2, 0.0), colour=(0.1, 0.1, 0.1))
    scene = Scene(table, (obj, box), False, 0)
    T = np.eye(4)  # looking along +y at the can's side from 0.8 m, 0.1 m up
    T[:3, :3] = np.column_stack([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    T[:3, 3] = (0.0, -0.8, 0.1)
    return scene, T


def test_material_dropouts_are_off_by_default_and_only_remove_depth():
    scene, T = _view((0.9, 0.9, 0.9))
    K = kinect_v1_intrinsics(W, H)
    plain = DepthSensor(K, W, H, seed=4).render_frame(scene, T, frame_seed=2)
    zero = DepthSensor(K, W, H, seed=4, dark_dropout=0.0, glossy_deg=0.0).render_frame(scene, T, frame_seed=2)
    assert np.array_equal(plain.depth, zero.depth) and np.array_equal(plain.color, zero.color)
    on = DepthSensor(K, W, H, seed=4, dark_dropout=0.8, glossy_deg=10.0).render_frame(scene, T, frame_seed=2)
    kept = on.depth > 0
    assert np.array_equal(on.depth[kept], plain.depth[kept]) and np.array_equal(on.color, plain.color)
    lost = (plain.depth > 0) & ~kept
    dark = plain.labels == scene.label_of("box")
    can = plain.labels == scene.label_of("can")
    share = lost[dark].sum() / max((plain.depth[dark] > 0).sum(), 1)
    assert 0.6 < share < 0.95  # about the asked 0.8 of the dark box's pixels
    assert lost[plain.labels == 2].mean() < 0.002  # the (light) table keeps its depth (but a jittered edge ray)
    # the glossy band on the can: a vertical band around the image column facing the camera, none at its rims
    cols = np.flatnonzero(lost[can.any(axis=1)].any(axis=0) & can.any(axis=0))
    can_cols = np.flatnonzero(can.any(axis=0))
    assert len(cols) > 2 and cols.min() > can_cols.min() + 2 and cols.max() < can_cols.max() - 2


def test_dark_blobs_are_clustered_not_salt_and_pepper():
    scene, T = _view((0.1, 0.1, 0.1))
    K = kinect_v1_intrinsics(W, H)
    plain = DepthSensor(K, W, H, seed=1, missing_rate=0.0, edge_dropout=0.0).render_frame(scene, T, frame_seed=0)
    on = DepthSensor(K, W, H, seed=1, missing_rate=0.0, edge_dropout=0.0, dark_dropout=0.5,
                     dropout_blob_px=4.0).render_frame(scene, T, frame_seed=0)
    can = (plain.labels == scene.label_of("can")) & (plain.depth > 0)
    lost = can & (on.depth == 0)
    # a lost pixel's right-hand neighbour on the can is lost far more often than the 0.5 base rate
    both = can[:, :-1] & can[:, 1:]
    assert np.sum(lost[:, :-1] & lost[:, 1:] & both) / max(np.sum(lost[:, :-1] & both), 1) > 0.8


@pytest.mark.parametrize("kw", [{"dark_dropout": 1.5}, {"glossy_deg": 90.0}, {"dropout_blob_px": -1.0}, {"dark_luma": 2.0}])
def test_bad_material_dropouts_raise_config_error(kw):
    with pytest.raises(ConfigError, match="material dropouts"):
        DepthSensor(kinect_v1_intrinsics(W, H), W, H, **kw)
