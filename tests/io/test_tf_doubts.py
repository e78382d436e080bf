"""TF data that lookups can use but should not trust silently: a frame published under two parents at once (two
publishers), and a link interpolated across a gap much longer than its usual spacing."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from recordings import K, T0, T_WORLD_BASE, T_WRIST_CAM, H, S, W, T_base_wrist, depth_mm, expected_pose

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import TransformError
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.tf_buffer import FOREVER_NS, TfBuffer
from kinfu_cli.io.writers import RecordingWriter

MS = 1_000_000


def _T(t) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = t
    return T


def _two_parent_recording(path, n=6):
    """world -> base_link (static) -> wrist (100 Hz) -> camera_optical (static), and a second publisher of wrist
    under world, 5 m off, in every /tf message."""
    far = _T([5.0, 5.0, 5.0])
    with RecordingWriter(path) as w:
        w.write_tf(T0, [("world", "base_link", T_WORLD_BASE), ("wrist", "camera_optical", T_WRIST_CAM)],
                   static=True)
        events = [(T0 + k * 10 * MS, "tf", k) for k in range(int((n / 30 + 0.2) * 100))]
        events += [(T0 + int(round(i / 30 * S)) + 50 * MS, "depth", i) for i in range(n)]
        for stamp, kind, i in sorted(events):
            if kind == "tf":
                w.write_tf(stamp, [("base_link", "wrist", T_base_wrist((stamp - T0) / S)), ("world", "wrist", far)])
            else:
                w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i), "16UC1")
                w.write_camera_info("/camera/depth/camera_info", stamp, "camera_optical", K, W, H)
    return path


def test_frame_under_two_parents_is_one_warning_and_its_frames_are_used(tmp_path):
    path = _two_parent_recording(tmp_path / "two.mcap")
    with open_recording(path) as rec:
        tf = TfBuffer.from_recording(rec)
        TfBuffer.from_recording(rec)  # read twice (roles, frames): still said once
        assert tf.parent_changes == []  # not one "changed parent" note per message
        assert len(rec.problems) == 1
        warning = rec.problems[0]
        for word in ("'wrist'", "'base_link'", "'world'", "2 parents", "take its link from 'base_link'",
                     "ignore its transforms from 'world'", "broken TF tree"):
            assert word in warning, word
        assert "m apart" in warning and float(warning.split("up to ")[1].split(" m")[0]) > 5.0
        stats = FrameStats()
        frames = list(iter_frames(rec, tf=tf, stats=stats))
    # every frame keeps its pose, through the parent the warning names (before: all but one dropped as "no camera
    # pose within the TF range", because each message threw the other parent's samples away)
    assert len(frames) == 6 and stats.dropped == {}
    for f in frames:
        np.testing.assert_allclose(f.T_world_camera, expected_pose(f.stamp_ns), atol=1e-6)

    res = CliRunner().invoke(cli, ["info", str(path)])
    assert res.exit_code == 0, res.output
    assert "changed parent" not in res.output
    assert res.output.count("published under 2 parents") == 1
    summary = json.loads(CliRunner().invoke(cli, ["info", str(path), "--json"]).output)
    assert summary["tf"]["tree"]["wrist"] == "base_link" and summary["tf"]["parent_changes"] == []


def test_the_parent_with_most_transforms_is_taken_and_a_one_way_reparenting_is_only_noted():
    tf = TfBuffer()
    for k in range(10):
        tf.add("a", "c", k * S, _T([1, 0, 0]))
        if k in (2, 6):  # stray transforms under another parent
            tf.add("b", "c", k * S + S // 2, _T([0, 9, 0]))
    tf.add("root", "a", 0, np.eye(4), static=True)
    tf.add("root", "b", 0, np.eye(4), static=True)
    assert tf.tree()["c"] == "a" and tf.parent_changes == []
    (warning,) = tf.parent_warnings()
    assert "'a' (10 transforms), 'b' (2 transforms)" in warning and "take its link from 'a'" in warning
    assert "the first seen" not in warning and "up to 9.06 m apart" in warning
    np.testing.assert_allclose(tf.lookup("root", "c", 6 * S + S // 2)[:3, 3], [1, 0, 0])

    grasped = TfBuffer()  # table -> gripper -> table (an object picked and put back): no broken tree to warn about
    for k, parent in enumerate(("table", "table", "gripper", "gripper", "table", "table")):
        grasped.add(parent, "obj", k * S, np.eye(4))
    assert grasped.parent_warnings() == []

    moved = TfBuffer()  # re-parented once (tf2 allows it): the later link, a note, no warning
    moved.add("a", "c", 0, np.eye(4))
    moved.add("b", "c", S, np.eye(4))
    assert moved.parent_changes == [("c", "a", "b")] and moved.tree()["c"] == "b"
    assert moved.parent_warnings() == []


def _gap_buffer() -> TfBuffer:
    """world -> arm at 10 Hz over 0..10 s, nothing from 0.6 to 9.0 s; arm -> cam at 10 Hz over 0..10 s."""
    tf = TfBuffer()
    for k in range(101):
        t = k * 100 * MS
        if not 600 * MS < t < 9 * S:
            tf.add("world", "arm", t, _T([t / S, 0, 0]))
        tf.add("arm", "cam", t, _T([0, 0, 0.01 * k]))
    return tf


def test_lookups_across_a_long_gap_are_counted_and_named():
    tf = _gap_buffer()
    tf.lookup("world", "cam", 300 * MS)  # before the gap
    for t in (1 * S, 2 * S, 2 * S, 5 * S + 3):  # one stamp twice: counted once
        tf.lookup("world", "cam", t)
    tf.lookup_many("world", "cam", np.array([600 * MS, 4 * S, 8 * S, 9 * S, 9500 * MS]))  # gap ends: not in it
    (warning,) = tf.gap_warnings()
    assert warning.startswith("TF link world -> arm has no transform for 8.400 s")
    assert "usually 0.1 s apart" in warning and "5 lookups fell in that gap" in warning
    assert tf.lookup("world", "cam", 5 * S)[0, 3] == pytest.approx(5.0)  # still interpolated, as tf2 does


def test_gap_checks_count_only_lookups_that_succeed_and_only_real_gaps():
    tf = _gap_buffer()
    tf.add("map", "world", 0, np.eye(4))
    tf.add("map", "world", 2 * S, np.eye(4))
    with pytest.raises(TransformError):  # the gap link (walked first) is fine at 5 s, but map -> world ends at 2 s
        tf.lookup("map", "cam", 5 * S)
    assert tf.gap_warnings() == []

    sparse = TfBuffer()  # 1 Hz with one 3 s step (3x its period) and a 0.45 s step at 50 Hz: no gaps
    for t in [0, 1, 2, 3, 6, 7, 8]:
        sparse.add("world", "a", t * S, np.eye(4))
    for k in range(50):
        sparse.add("a", "b", k * 20 * MS + (450 * MS if k >= 25 else 0), np.eye(4))
    sparse.lookup_many("world", "b", np.arange(0, 1400 * MS, 10 * MS))
    sparse.lookup("world", "b", 700 * MS)
    assert sparse.gap_warnings() == []


def test_frames_interpolated_across_a_tf_gap_are_counted(tmp_path):
    """The frame assembly's lookups (one stamp each) are the ones counted: 4 of 8 depth frames fall in the gap."""
    path = tmp_path / "gap.mcap"
    with RecordingWriter(path) as w:
        w.write_tf(T0, [("world", "base_link", T_WORLD_BASE), ("wrist", "camera_optical", T_WRIST_CAM)],
                   static=True)
        events = [(T0 + k * 100 * MS, "tf", k) for k in range(101) if not 6 < k < 90]
        events += [(T0 + (500 + 200 * i if i < 5 else 9200 + 200 * (i - 5)) * MS, "depth", i) for i in range(8)]
        for stamp, kind, i in sorted(events):
            if kind == "tf":
                w.write_tf(stamp, [("base_link", "wrist", T_base_wrist((stamp - T0) / S))])
            else:
                w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i), "16UC1")
                w.write_camera_info("/camera/depth/camera_info", stamp, "camera_optical", K, W, H)
    with open_recording(path) as rec:
        tf = TfBuffer.from_recording(rec)
        assert len(list(iter_frames(rec, tf=tf))) == 8
    (warning,) = tf.gap_warnings()
    assert "base_link -> wrist has no transform for 8.400 s" in warning and "4 lookups fell in that gap" in warning


def test_a_reparented_frame_is_looked_up_through_the_parent_it_had_at_the_stamp():
    """tf2 keeps a frame's parent per transform. Before, only the latest parent's link was kept: a frame re-parented
    once was out of TF range before the change (its frames dropped), and an object picked and put back took the
    table's link for the whole span, interpolated across the time the gripper held it."""
    tf = TfBuffer()
    tf.add("world", "table", 0, _T([1, 0, 0]), static=True)
    for k in range(11):  # the gripper sweeps along y, 1 m a second
        tf.add("world", "gripper", k * S, _T([0, k, 0]))
    for k, parent in enumerate(["table"] * 3 + ["gripper"] * 4 + ["table"] * 4):  # picked at 3 s, put back at 7 s
        tf.add(parent, "obj", k * S, _T([0, 0, 0.5 if parent == "table" else -0.1]))
    assert tf.parent_warnings() == [] and tf.tree()["obj"] == "table"
    np.testing.assert_allclose(tf.lookup("world", "obj", 1 * S + S // 2)[:3, 3], [1, 0, 0.5])
    np.testing.assert_allclose(tf.lookup("world", "obj", 4 * S + S // 2)[:3, 3], [0, 4.5, -0.1])  # in the gripper
    np.testing.assert_allclose(tf.lookup("world", "obj", 8 * S)[:3, 3], [1, 0, 0.5])
    stamps = np.array([1, 4, 5, 8, 2]) * S
    many = tf.lookup_many("world", "obj", stamps)
    np.testing.assert_allclose(many[:, :3, 3], [[1, 0, 0.5], [0, 4, -0.1], [0, 5, -0.1], [1, 0, 0.5], [1, 0, 0.5]])
    assert tf.time_range("world", "obj") == (0, 10 * S)

    moved = TfBuffer()  # re-parented once: the old parent before the change, the new one after
    moved.add("world", "a", 0, _T([1, 0, 0]), static=True)
    moved.add("world", "b", 0, _T([0, 2, 0]), static=True)
    for k in range(6):
        moved.add("a" if k < 3 else "b", "c", k * S, np.eye(4))
    assert moved.parent_changes == [("c", "a", "b")] and moved.tree()["c"] == "b"
    np.testing.assert_allclose(moved.lookup("world", "c", S)[:3, 3], [1, 0, 0])  # was: outside the buffered range
    np.testing.assert_allclose(moved.lookup("world", "c", 4 * S)[:3, 3], [0, 2, 0])
    assert moved.time_range("world", "c") == (0, 5 * S)


def test_frames_interpolated_across_a_pose_topic_gap_are_counted(tmp_path):
    """A camera pose topic that stops for 8.4 s: its poses were interpolated across the gap without a word (the TF
    gap check did not look at pose topics)."""
    path = tmp_path / "pose_gap.mcap"
    with RecordingWriter(path) as w:
        events = [(T0 + k * 100 * MS, "pose", k) for k in range(101) if not 6 < k < 90]
        events += [(T0 + (500 + 200 * i if i < 5 else 9200 + 200 * (i - 5)) * MS, "depth", i) for i in range(8)]
        for stamp, kind, i in sorted(events):
            if kind == "pose":
                w.write_pose("/camera/pose", stamp, "world", expected_pose(stamp))
            else:
                w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i), "16UC1")
                w.write_camera_info("/camera/depth/camera_info", stamp, "camera_optical", K, W, H)
    stats = FrameStats()
    with open_recording(path) as rec:
        assert len(list(iter_frames(rec, pose_source="topic", pose_topic="/camera/pose", stats=stats))) == 8
    (warning,) = [n for n in stats.notes if "pose topic /camera/pose" in n]
    assert "no transform for 8.400 s" in warning and "4 lookups fell in that gap" in warning
    assert "__camera__" not in warning and str(path) in warning


def _tripod_buffer(picks: list[tuple[float, float]], late: set[int] = frozenset(), static_tripod: bool = False,
                   linked: bool = True) -> TfBuffer:
    """A camera on a wrist that sweeps along y (1 m/s, TF at 10 Hz) and on a tripod at x = 2 during `picks`
    (start, end s); `late`: tick numbers whose wrist message is logged last (stamps still in order)."""
    tf = TfBuffer()
    for k in range(101):
        tf.add("world", "wrist", k * S // 10, _T([0, k / 10, 0]))
    if linked:
        tf.add("world", "tripod", 0, _T([2, 0, 0]), static=True)
    ticks = sorted(range(101), key=lambda k: (k in late, k))
    for k in ticks:
        t = k / 10
        on = any(a <= t < b for a, b in picks)
        if on and static_tripod:
            if not any(a <= t - 0.1 < b for a, b in picks):  # one static transform when it moves there
                tf.add("tripod", "cam", k * S // 10, np.eye(4), static=True)
            continue
        tf.add("tripod" if on else "wrist", "cam", k * S // 10, _T([0, 0, 0.1]))
    return tf


def test_a_reparented_camera_follows_its_parents_in_stamp_order_not_message_order():
    """The wrist's last camera transforms before the move, logged late, made the camera read as under two parents
    at once (7 switches in message order): 18 of 30 poses were dropped."""
    tf = _tripod_buffer([(4.0, 99.0)], late={37, 38, 39})
    assert tf.parent_warnings() == [] and tf.parent_changes == [("cam", "wrist", "tripod")]
    np.testing.assert_allclose(tf.lookup("world", "cam", 35 * S // 10)[:3, 3], [0, 3.5, 0.1])
    np.testing.assert_allclose(tf.lookup("world", "cam", 50 * S // 10)[:3, 3], [2, 0, 0.1])


def test_an_object_picked_and_put_back_again_and_again_is_not_two_publishers():
    """Two picks (4 parent switches) were read as a broken tree: the tripod spans were interpolated through the
    wrist, up to 0.6 m off, with a warning blaming two publishers."""
    tf = _tripod_buffer([(2.0, 4.0), (6.0, 8.0)])
    assert tf.parent_warnings() == [] and len(tf.parent_changes) == 4
    for t, where in ((1.0, [0, 1, 0.1]), (3.0, [2, 0, 0.1]), (5.0, [0, 5, 0.1]), (7.0, [2, 0, 0.1]),
                     (9.0, [0, 9, 0.1])):
        np.testing.assert_allclose(tf.lookup("world", "cam", int(t * S))[:3, 3], where)
    many = tf.lookup_many("world", "cam", np.array([1.0, 3.0, 5.0, 7.0, 9.0]) * S)
    np.testing.assert_allclose(many[:, 0, 3], [0, 2, 0, 2, 0])


def test_a_camera_moved_onto_a_static_parent_keeps_its_arm_poses_before():
    """Re-parenting onto a /tf_static link gave the static pose for the whole recording (1.1 m off before)."""
    tf = _tripod_buffer([(4.0, 99.0)], static_tripod=True)
    np.testing.assert_allclose(tf.lookup("world", "cam", 2 * S)[:3, 3], [0, 2, 0.1])
    np.testing.assert_allclose(tf.lookup("world", "cam", 6 * S)[:3, 3], [2, 0, 0])
    assert tf.time_range("world", "cam") == (0, FOREVER_NS)  # on the tripod for ever after


def test_a_stamp_between_two_runs_holds_the_earlier_runs_last_transform():
    """tf2 takes the earlier of two samples under different parents; the lookup failed as out of range."""
    tf = TfBuffer()
    tf.add("world", "a", 0, _T([1, 0, 0]), static=True)
    tf.add("world", "b", 0, _T([0, 2, 0]), static=True)
    for k in range(4):
        tf.add("a", "c", k * S, _T([0, 0, k]))
    for k in range(6, 9):
        tf.add("b", "c", k * S, np.eye(4))
    np.testing.assert_allclose(tf.lookup("world", "c", 5 * S)[:3, 3], [1, 0, 3])  # a's last transform (3 s)
    with pytest.raises(TransformError):  # after the last run: out of range as before
        tf.lookup("world", "c", 9 * S)


def test_a_camera_moved_onto_an_unlinked_parent_is_connected_for_the_time_before():
    """Connectivity was decided on the latest tree only: a camera moved onto a tripod linked to nothing failed the
    whole run, though its first 4 s had a chain to the world."""
    tf = _tripod_buffer([(4.0, 99.0)], linked=False)
    assert tf.connected("world", "cam") and tf.chain("cam") == ["cam", "tripod"]
    np.testing.assert_allclose(tf.lookup("world", "cam", 2 * S)[:3, 3], [0, 2, 0.1])
    with pytest.raises(TransformError):
        tf.lookup("world", "cam", 6 * S)
    assert tf.time_range("world", "cam")[0] == 0


def test_a_gap_on_an_earlier_parents_link_is_still_said():
    tf = TfBuffer()
    for k in [*range(0, 14), *range(35, 40)]:
        tf.add("world", "cam", k * S // 10, _T([0, k / 10, 0]))
    for k in range(40, 60):
        tf.add("tripod", "cam", k * S // 10, np.eye(4))
    tf.add("world", "tripod", 0, np.eye(4), static=True)
    tf.lookup("world", "cam", 2 * S)
    (warning,) = tf.gap_warnings()
    assert "TF link world -> cam has no transform for 2.200 s" in warning


def test_lookups_are_covered_wherever_some_runs_chain_reaches_the_world():
    """A tool under the arm (0-5 s), then under a cart whose own link exists only from 5 s: time_range took the
    cart's range and dropped the first half of the hand samples without a word."""
    tf = TfBuffer()
    for k in range(101):
        tf.add("world", "arm", k * S // 10, _T([0, k / 10, 0]))
        if k >= 50:
            tf.add("world", "cart", k * S // 10, _T([3, 0, 0]))
        tf.add("arm" if k < 50 else "cart", "tool", k * S // 10, _T([0, 0, 1]))
    assert tf.time_range("world", "tool") == (0, 10 * S)
    stamps = np.array([1, 4, 6, 9]) * S
    assert tf.covers("world", "tool", stamps).all()
    np.testing.assert_allclose(tf.lookup_many("world", "tool", stamps)[:, :3, 3],
                               [[0, 1, 1], [0, 4, 1], [3, 0, 1], [3, 0, 1]])
    assert not tf.is_static("tool")


def test_a_frame_set_down_on_a_static_parent_still_moves_and_loops_of_one_run_are_found():
    tf = TfBuffer()
    for k in range(10):
        tf.add("world", "arm", k * S, _T([0, k, 0]))
    for k in range(5):
        tf.add("arm", "tool", k * S, np.eye(4))
    tf.add("world", "table", 0, np.eye(4), static=True)
    tf.add("table", "tool", 5 * S, np.eye(4), static=True)  # set down at 5 s
    assert tf.tree()["tool"] == "table" and not tf.is_static("tool")
    looped = TfBuffer()
    looped.add("A", "tool", 0, np.eye(4), static=True)  # tool hangs from A: A under tool at 4 s is a loop
    for k in range(10):
        looped.add("tool" if k == 4 else "world", "A", k * S, np.eye(4))
    assert ["A", "tool", "A"] in looped.loops() or ["tool", "A", "tool"] in looped.loops()
    assert not looped.covers("world", "A", np.array([4 * S + S // 2])).any()  # the loop's time is not covered
    assert looped.covers("world", "A", np.array([2 * S, 7 * S])).all()


def test_frequent_picks_at_a_low_tf_rate_are_not_two_publishers():
    """An object picked every second with TF at 10 Hz switches at 20 % of its transforms, in runs of 5: read as two
    publishers, every lookup took the table (9 m from the gripper)."""
    tf = TfBuffer()
    tf.add("world", "table", 0, _T([9, 0, 0]), static=True)
    tf.add("world", "gripper", 0, np.eye(4), static=True)
    for k in range(200):
        tf.add("gripper" if (k // 5) % 2 else "table", "obj", k * S // 10, np.eye(4))
    assert tf.parent_warnings() == []
    np.testing.assert_allclose(tf.lookup("world", "obj", 7 * S // 10)[:3, 3], [0, 0, 0])  # in the gripper
    np.testing.assert_allclose(tf.lookup("world", "obj", 12 * S // 10)[:3, 3], [9, 0, 0])


def test_a_moving_link_later_sent_on_tf_static_keeps_its_samples():
    """The static message threw the link's /tf samples away: every lookup then read the static value."""
    tf = TfBuffer()
    for k in range(10):
        tf.add("world", "c", k * S, _T([k / 10, 0, 0]))
    tf.add("world", "c", 10 * S, _T([7, 0, 0]), static=True)
    np.testing.assert_allclose(tf.lookup("world", "c", 2 * S)[:3, 3], [0.2, 0, 0])
    np.testing.assert_allclose(tf.lookup("world", "c", 10 * S)[:3, 3], [7, 0, 0])


def test_frames_where_the_chain_is_broken_are_told_from_frames_outside_the_tf_time(tmp_path):
    """Frames after the camera moved onto a tripod linked to nothing were counted as 'no camera pose within the TF
    range', though TF ran all along: the chain was broken there, which the drop reason now says."""
    from kinfu_cli.io.frames import DROP_CHAIN_BROKEN, DROP_NO_POSE
    path = tmp_path / "moved.mcap"
    with RecordingWriter(path) as w:
        w.write_tf(T0, [("world", "base_link", T_WORLD_BASE)], static=True)
        events = [(T0 + 200 * MS + k * 10 * MS, "tf", k) for k in range(60)]  # TF from 0.2 s to 0.79 s
        events += [(T0 + i * 100 * MS + 50 * MS, "depth", i) for i in range(10)]  # 0.05 .. 0.95 s
        for stamp, kind, i in sorted(events):
            if kind == "tf":
                on_tripod = stamp >= T0 + 500 * MS
                w.write_tf(stamp, [("base_link", "wrist", T_base_wrist((stamp - T0) / S)),
                                   ("tripod" if on_tripod else "wrist", "camera_optical", T_WRIST_CAM)])
            else:
                w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i), "16UC1")
                w.write_camera_info("/camera/depth/camera_info", stamp, "camera_optical", K, W, H)
    with open_recording(path) as rec:
        stats = FrameStats()
        frames = list(iter_frames(rec, stats=stats, tolerance_s=0.0))
    # 0.05, 0.15 s: before TF; 0.25 .. 0.45 s: on the wrist; 0.55 .. 0.75 s: on the unlinked tripod (the last run's
    # transforms end at 0.79 s); 0.85, 0.95 s: after TF
    assert [f.index for f in frames] == [2, 3, 4]
    assert stats.dropped == {DROP_NO_POSE: 4, DROP_CHAIN_BROKEN: 3}
