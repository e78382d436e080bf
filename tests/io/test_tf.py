"""TfBuffer: slerp interpolation, chains through several frames, inverse direction, clear errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from kinfu_cli.core.errors import TransformError
from kinfu_cli.io.tf_buffer import TfBuffer

S = 1_000_000_000


def _T(rotvec, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def test_interpolation_is_linear_in_translation_and_slerp_in_rotation():
    tf = TfBuffer()
    T0, T1 = _T([0, 0, 0.2], [0, 0, 0]), _T([0.3, -0.4, 1.5], [1.0, 2.0, -4.0])
    tf.add("world", "arm", 10 * S, T0)
    tf.add("world", "arm", 12 * S, T1)
    for a in (0.0, 0.25, 0.5, 0.9, 1.0):
        got = tf.lookup("world", "arm", int(10 * S + a * 2 * S))
        np.testing.assert_allclose(got[:3, 3], (1 - a) * T0[:3, 3] + a * T1[:3, 3], atol=1e-12)
        ref = Slerp([0, 1], Rotation.from_matrix([T0[:3, :3], T1[:3, :3]]))([a]).as_matrix()[0]
        np.testing.assert_allclose(got[:3, :3], ref, atol=1e-9)
    # exact samples come back exactly, and many stamps at once agree with one at a time
    stamps = np.array([10 * S, 11 * S, 12 * S])
    many = tf.lookup_many("world", "arm", stamps)
    for s, T in zip(stamps, many):
        np.testing.assert_allclose(T, tf.lookup("world", "arm", int(s)), atol=1e-12)
    np.testing.assert_allclose(many[0], T0, atol=1e-12)
    np.testing.assert_allclose(many[2], T1, atol=1e-12)


def test_slerp_takes_the_short_way_round():
    tf = TfBuffer()
    tf.add("a", "b", 0, _T([0, 0, np.deg2rad(170)], [0, 0, 0]))
    tf.add("a", "b", 2 * S, _T([0, 0, np.deg2rad(-170)], [0, 0, 0]))
    mid = tf.lookup("a", "b", S)
    angle = np.rad2deg(Rotation.from_matrix(mid[:3, :3]).as_rotvec())
    np.testing.assert_allclose(np.abs(angle[2]), 180.0, atol=1e-6)  # through 180, not through 0


def test_chain_and_inverse_direction():
    tf = TfBuffer()
    links = [("world", "base", _T([0, 0, 0.5], [1, 0, 0])), ("base", "l1", _T([0.2, 0, 0], [0, 0, 0.3])),
             ("l1", "wrist", _T([0, 0.4, 0], [0.1, 0.2, 0])), ("world", "table", _T([0, 0, -1], [0, 3, 0]))]
    for p, c, T in links[:3]:
        tf.add(p, c, 0, T)
        tf.add(p, c, 4 * S, T)
    tf.add("wrist", "camera", 0, _T([0.1, 0.1, 0.1], [0, 0, 0.05]), static=True)
    tf.add(*links[3][:2], 0, links[3][2], static=True)
    T_world_cam = links[0][2] @ links[1][2] @ links[2][2] @ _T([0.1, 0.1, 0.1], [0, 0, 0.05])
    np.testing.assert_allclose(tf.lookup("world", "camera", 2 * S), T_world_cam, atol=1e-12)
    np.testing.assert_allclose(tf.lookup("camera", "world", 2 * S), np.linalg.inv(T_world_cam), atol=1e-12)
    # across branches: table <- camera goes up to world and down again
    np.testing.assert_allclose(tf.lookup("table", "camera", S), np.linalg.inv(links[3][2]) @ T_world_cam, atol=1e-12)
    np.testing.assert_allclose(tf.lookup("camera", "camera", S), np.eye(4), atol=0)
    assert tf.tree() == {"base": "world", "l1": "base", "wrist": "l1", "camera": "wrist", "table": "world"}
    assert tf.frames() == ["base", "camera", "l1", "table", "world", "wrist"]
    assert tf.time_range("world", "camera") == (0, 4 * S)
    assert tf.time_range("world", "table") is None  # static only


def test_errors_name_frames_and_range():
    tf = TfBuffer()
    tf.add("world", "arm", 10 * S, np.eye(4))
    tf.add("world", "arm", 20 * S, np.eye(4))
    tf.add("odom", "robot", 0, np.eye(4), static=True)
    with pytest.raises(TransformError, match=r"outside the buffered range \[10.000, 20.000\] s"):
        tf.lookup("world", "arm", 25 * S)
    with pytest.raises(TransformError, match=r"time 9.000 s"):
        tf.lookup("arm", "world", 9 * S)
    # a tolerance clamps to the end sample
    np.testing.assert_allclose(tf.lookup("world", "arm", 20 * S + 10, tolerance_ns=100), np.eye(4))
    with pytest.raises(TransformError, match="'hand' is not in the TF tree"):
        tf.lookup("world", "hand", 15 * S)
    with pytest.raises(TransformError, match="robot") as exc:
        tf.lookup("world", "robot", 15 * S)
    assert "world" in str(exc.value) and "no chain" in str(exc.value)
    with pytest.raises(TransformError, match="4x4"):
        tf.add("a", "b", 0, np.eye(3))
    assert tf.connected("arm", "world") and not tf.connected("world", "robot") and not tf.connected("x", "world")
    with pytest.raises(TransformError, match="no chain"):
        tf.require_chain("robot", "arm")


def test_leading_slashes_and_duplicate_stamps():
    tf = TfBuffer()
    tf.add("/world", "/arm", S, _T([0, 0, 0], [1, 0, 0]))
    tf.add("world", "arm", S, _T([0, 0, 0], [2, 0, 0]))  # same stamp: the later sample wins
    tf.add("world", "arm", 2 * S, _T([0, 0, 0], [4, 0, 0]))
    assert tf.link_stamps("arm").tolist() == [S, 2 * S]
    np.testing.assert_allclose(tf.lookup("world", "arm", int(1.5 * S))[:3, 3], [3, 0, 0])


def test_bad_transforms_in_messages_are_skipped_and_counted():
    from types import SimpleNamespace as NS

    def tr(parent, child, w):
        return NS(header=NS(frame_id=parent, stamp=NS(sec=1, nanosec=0)), child_frame_id=child,
                  transform=NS(translation=NS(x=1.0, y=2.0, z=3.0), rotation=NS(x=0.0, y=0.0, z=0.0, w=w)))

    tf = TfBuffer()
    n = tf.add_message(NS(transforms=[tr("world", "a", 1.0), tr("", "b", 1.0), tr("world", "c", 0.0),
                                      tr("a", "a", 1.0)]))
    assert n == 1 and tf.tree() == {"a": "world"}
    assert sum(tf.rejected.values()) == 3
    assert any("zero quaternion" in r for r in tf.rejected)
    np.testing.assert_allclose(tf.lookup("world", "a", S)[:3, 3], [1, 2, 3])


@pytest.mark.parametrize("translation, quat, reason", [
    ((0, 0, 0), (np.nan, 0, 0, 1), "non-finite quaternion"),
    ((0, 0, 0), (0, 0, 0, np.inf), "non-finite quaternion"),
    ((0, 0, 0), (0, 0, 0, 0), "zero quaternion"),
    ((0, 0, 0), (0, 0, 0, 2.0), "not of unit length"),
    ((0, 0, 0), (0, 0, 0, 0.99), "not of unit length"),  # |q|^2 = 0.9801: off by more than tf2's 0.01
    ((np.inf, 0, 0), (0, 0, 0, 1), "non-finite translation"),
    ((0, np.nan, 0), (0, 0, 0, 1), "non-finite translation"),
    ((0, 0, 3e200), (0, 0, 0, 1), "translation beyond"),
])
def test_transforms_are_validated_on_the_way_in(translation, quat, reason):
    tf = TfBuffer()
    with pytest.raises(TransformError, match=reason) as exc:
        tf.add_quat("world", "arm", S, translation, quat)
    assert "'world' -> 'arm'" in str(exc.value) and tf.frames() == []
    # tf2's tolerance: |q|^2 within 0.01 of 1 is accepted, and stored normalised
    tf.add_quat("world", "arm", S, (1, 2, 3), (0, 0, 0, 1.004))
    np.testing.assert_allclose(tf.lookup("world", "arm", S)[:3, :3], np.eye(3), atol=1e-12)


def test_rejected_transforms_are_recorded_per_link():
    from types import SimpleNamespace as NS

    def tr(parent, child, x=0.0, w=1.0):
        return NS(header=NS(frame_id=parent, stamp=NS(sec=1, nanosec=0)), child_frame_id=child,
                  transform=NS(translation=NS(x=x, y=0.0, z=0.0), rotation=NS(x=0.0, y=0.0, z=0.0, w=w)))

    tf = TfBuffer()
    assert tf.add_message(NS(transforms=[tr("world", "base"), tr("base", "arm", w=2.0), tr("base", "arm", x=np.nan),
                                         tr("arm", "arm")])) == 1
    assert tf.rejected_links == {("base", "arm"): {"quaternion not of unit length (| |q|^2 - 1 | >= 0.01)": 1,
                                                   "non-finite translation": 1},
                                 ("arm", "arm"): {"expected two different, non-empty frame names": 1}}
    assert tf.tree() == {"base": "world"}
    # a chain that stops at a frame whose link was rejected says so, naming the link and the reason
    tf.add("arm", "camera", S, np.eye(4))
    text = tf.broken_chain("camera", "world")
    assert "stops at 'arm'" in text and "'world'" in text and "'base' -> 'arm'" in text and "unit length" in text


def test_loops_are_detected_not_walked_forever():
    tf = TfBuffer()
    for parent, child in [("world", "a"), ("a", "b"), ("b", "c"), ("c", "d"), ("d", "b"), ("x", "y"), ("y", "x")]:
        tf.add(parent, child, 0, np.eye(4))
    assert tf.parent_changes == [("b", "a", "d")]  # the later link d -> b replaced a -> b
    assert tf.loops() == [["b", "c", "d", "b"], ["x", "y", "x"]]
    for call in (lambda: tf.chain("d"), lambda: tf.lookup("world", "d", 0), lambda: tf.connected("c", "world"),
                 lambda: tf.time_range("world", "c")):
        try:
            result = call()
        except TransformError as exc:
            assert "form a loop" in str(exc) and all(f"{f} ->" in str(exc) for f in "bcd")
        else:
            assert result is False  # connected() answers instead of raising
    assert tf.chain("a") == ["a", "world"]
