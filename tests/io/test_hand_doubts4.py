"""A hand pose topic whose frame_id changes mid-stream is brought into the world frame (not into its first frame,
which may be a moving arm link), and an empty frame_id is the frame of the sample before it."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.io.hand import load_hand_trajectory
from kinfu_cli.io.writers import RecordingWriter
from tests.recordings import T0, T_WORLD_BASE, S

HAND = np.array([0.1, 0.2, 0.3])  # the hand stays at one place in the world (and in 'table' below)
N = 20


def _T_base_link3(k: int) -> np.ndarray:
    """A moving arm link: 5 cm further along x at each sample."""
    T = np.eye(4)
    T[:3, 3] = [0.05 * k, 0.1, 0.2]
    return T


def _at(T_frame: np.ndarray) -> np.ndarray:
    """The hand's pose in a frame whose pose in the world is T_frame."""
    T = np.eye(4)
    T[:3, 3] = HAND
    return np.linalg.inv(T_frame) @ T


def _write(path, frame_of, root="world", other_tree=False):
    """TF root -> base_link (static) -> link3 (moving); /hand/pose sample k in frame_of(k) = (frame_id written,
    frame its coordinates are in)."""
    with RecordingWriter(path) as w:
        w.write_tf(T0, [(root, "base_link", T_WORLD_BASE)], static=True)
        if other_tree:  # a 'world' the hand's frames are not linked to
            w.write_tf(T0, [("world", "mocap", np.eye(4))], static=True)
        for k in range(N):
            stamp = T0 + k * S // 10
            w.write_tf(stamp, [("base_link", "link3", _T_base_link3(k))])
        for k in range(N):
            stamp = T0 + k * S // 10
            written, coords = frame_of(k)
            pose_of = {root: np.eye(4), "base_link": T_WORLD_BASE, "link3": T_WORLD_BASE @ _T_base_link3(k)}
            w.write_pose("/hand/pose", stamp, written, _at(pose_of[coords]))
    return path


def test_first_frame_a_moving_link_is_not_the_target(tmp_path):
    path = _write(tmp_path / "l3.mcap", lambda k: ("link3", "link3") if k < 10 else ("world", "world"))
    traj = load_hand_trajectory(path)
    assert traj.frame == "world"  # was 'link3': the hand then moved with the arm
    np.testing.assert_allclose(traj.positions, np.tile(HAND, (N, 1)), atol=1e-9)
    said = [p for p in traj.meta["recording_problems"] if "changes frame_id" in p]
    assert len(said) == 1 and "10 samples in other frames than 'world'" in said[0]


def test_without_a_linked_world_a_statically_rooted_frame_is_the_target(tmp_path):
    path = _write(tmp_path / "tab.mcap", lambda k: ("link3", "link3") if k < 10 else ("base_link", "base_link"),
                  root="table", other_tree=True)
    traj = load_hand_trajectory(path)
    assert traj.frame == "base_link"  # hangs from the root 'table' by a static link; link3 moves
    expected = (np.linalg.inv(T_WORLD_BASE) @ np.append(HAND, 1.0))[:3]
    np.testing.assert_allclose(traj.positions, np.tile(expected, (N, 1)), atol=1e-9)


def _with_empty(k: int) -> tuple[str, str]:
    """base_link then link3, every third frame_id left empty (its coordinates in the frame before it)."""
    frame = "base_link" if k < 10 else "link3"
    return ("" if k % 3 == 0 else frame), frame


@pytest.mark.parametrize("world_frame", [None, "world"])
def test_empty_frame_id_is_the_frame_before_it(tmp_path, world_frame):
    traj = load_hand_trajectory(_write(tmp_path / "e.mcap", _with_empty), world_frame=world_frame)
    assert traj.frame == "world"
    np.testing.assert_allclose(traj.positions, np.tile(HAND, (N, 1)), atol=1e-9)  # '' was read as the target


def test_leading_empty_frame_ids_take_the_first_frame(tmp_path):
    path = _write(tmp_path / "lead.mcap",
                  lambda k: ("", "link3") if k < 3 else (("link3", "link3") if k < 10 else ("world", "world")))
    traj = load_hand_trajectory(path)
    np.testing.assert_allclose(traj.positions, np.tile(HAND, (N, 1)), atol=1e-9)


def test_samples_without_frame_id_are_counted_in_a_warning(tmp_path):
    """Which frame an empty frame_id meant is a guess: the number of samples it was made for is said."""
    traj = load_hand_trajectory(_write(tmp_path / "count.mcap", _with_empty))
    said = [p for p in traj.meta["recording_problems"] if "without frame_id" in p]
    assert len(said) == 1 and f"{sum(1 for k in range(N) if k % 3 == 0)} samples without frame_id" in said[0]
