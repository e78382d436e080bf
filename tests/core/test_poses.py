"""core.poses: the one look_at, scipy-backed quaternion conversions, rigidity checks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinfu_cli.core.errors import ConfigError, TransformError, VolumeError
from kinfu_cli.core.poses import check_poses, check_rigid, look_at, matrix_to_quaternion, quaternion_to_matrix


def test_look_at_points_the_optical_axis_at_the_target_with_an_upright_image():
    eye, target = np.array([1.0, -0.5, 1.2]), np.array([0.1, 0.2, 0.7])
    T = look_at(eye, target)
    z = (target - eye) / np.linalg.norm(target - eye)
    assert np.allclose(T[:3, 2], z) and np.allclose(T[:3, 3], eye)
    assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3)) and np.isclose(np.linalg.det(T[:3, :3]), 1.0)
    assert T[2, 1] < 0  # image y (down) points away from world up
    assert abs(T[2, 0]) < 1e-12  # image x is horizontal: level horizon


@pytest.mark.parametrize("direction", [(0, 0, -1), (0, 0, 1), (1, 0, 0)])
def test_look_at_along_up_still_gives_a_rotation(direction):
    T = look_at((0, 0, 0), direction)
    assert np.allclose(T[:3, 2], direction)
    assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3))


def test_look_at_refuses_a_target_at_the_eye():
    with pytest.raises(ConfigError, match="target"):
        look_at((1, 2, 3), (1, 2, 3))


def test_quaternions_round_trip_with_w_non_negative_and_match_scipy():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    R = quaternion_to_matrix(q)
    assert np.allclose(R, Rotation.from_quat(q).as_matrix(), atol=1e-15)
    back = matrix_to_quaternion(R)
    assert np.all(back[:, 3] >= 0)
    unit = q / np.linalg.norm(q, axis=1, keepdims=True)
    assert np.allclose(np.abs(np.sum(back * unit, axis=1)), 1.0)
    assert quaternion_to_matrix([0, 0, 0, 2.0]).shape == (3, 3)
    assert matrix_to_quaternion(R.reshape(5, 10, 3, 3)).shape == (5, 10, 4)


@pytest.mark.parametrize("q", [[0, 0, 0, 0], [np.nan, 0, 0, 1], [np.inf, 0, 0, 1]])
def test_degenerate_quaternion_is_a_transform_error(q):
    with pytest.raises(TransformError, match="zero or non-finite norm"):
        quaternion_to_matrix(q)


def test_rigidity_checks_name_what_is_wrong():
    T = np.eye(4)
    assert np.array_equal(check_rigid(T), T)
    with pytest.raises(VolumeError, match="not finite"):
        check_rigid(np.full((4, 4), np.nan))
    S = np.eye(4)
    S[0, 0] = 2.0
    with pytest.raises(VolumeError, match="not rigid"):
        check_rigid(S)
    with pytest.raises(ConfigError, match="cands: pose 1 is not a rigid"):
        check_poses([np.eye(4), S], source="cands")
    assert check_poses(np.eye(4)).shape == (1, 4, 4)
