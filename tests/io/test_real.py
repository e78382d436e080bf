"""Recordings written by real ROS tools (../shared/data/ros-recordings): containers, TF and pose streams."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.io.messages import pose_message_to_matrix, time_to_ns, transform_to_matrix
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.tf_buffer import TfBuffer


@pytest.fixture
def rr(shared_data):
    return lambda name: shared_data("ros-recordings", name)


def _tf_samples(rec):
    out = []
    for topic, _, msg in rec.messages(["/tf", "/tf_static"]):
        for tr in msg.transforms:
            out.append((topic, tr.header.frame_id, tr.child_frame_id, time_to_ns(tr.header.stamp),
                        transform_to_matrix(tr.transform)))
    return out


def test_tf_example_bag_and_ros2_folder_agree(rr):
    with open_recording(rr("tf_example.bag")) as bag, open_recording(rr("tf_example")) as ros2:
        assert bag.format == "bag" and ros2.format == "ros2"
        for rec in (bag, ros2):
            assert rec.topics["/tf"].count == 517 and rec.topics["/tf_static"].count == 1
            assert rec.topics["/tf"].msgtype == "tf2_msgs/msg/TFMessage"
            assert 51 < rec.duration_s < 53  # "about 52 s"
            assert rec.topics["/tf"].rate_hz == pytest.approx(10.0, rel=1e-3)
        assert bag.start_ns == ros2.start_ns and bag.end_ns == ros2.end_ns
        a, b = _tf_samples(bag), _tf_samples(ros2)
        assert len(a) == len(b) == 518
        for x, y in zip(a, b):
            assert x[:4] == y[:4]
            np.testing.assert_array_equal(x[4], y[4])
        tf_bag, tf_ros2 = TfBuffer.from_recording(bag), TfBuffer.from_recording(ros2)
    assert tf_bag.tree() == tf_ros2.tree() == {"base_footprint": "odom", "base_link": "base_footprint"}
    assert not tf_bag.is_static("base_footprint") and tf_bag.is_static("base_link")
    # a lookup at a raw message's stamp gives that message's transform, chained through the static link
    _, _, _, stamp, T_odom_fp = a[200]
    T_fp_base = next(s[4] for s in a if s[0] == "/tf_static")
    for tf in (tf_bag, tf_ros2):
        np.testing.assert_allclose(tf.lookup("odom", "base_footprint", stamp), T_odom_fp, atol=1e-12)
        np.testing.assert_allclose(tf.lookup("odom", "base_link", stamp), T_odom_fp @ T_fp_base, atol=1e-12)
        np.testing.assert_allclose(tf.lookup("base_link", "odom", stamp), np.linalg.inv(T_odom_fp @ T_fp_base),
                                   atol=1e-9)
    # half-way between two samples: translation half-way
    s0, s1 = a[300][3], a[301][3]
    mid = tf_bag.lookup("odom", "base_footprint", (s0 + s1) // 2)
    np.testing.assert_allclose(mid[:3, 3], (a[300][4][:3, 3] + a[301][4][:3, 3]) / 2, atol=1e-6)


def test_zstd_mcap_odometry_amcl_and_tf(rr):
    with open_recording(rr("nav2_turtlebot.mcap")) as rec:
        assert rec.format == "mcap"
        assert rec.topics["/odom"].msgtype == "nav_msgs/msg/Odometry"
        assert rec.topics["/amcl_pose"].msgtype == "geometry_msgs/msg/PoseWithCovarianceStamped"
        assert set(rec.topics) == {"/tf", "/tf_static", "/odom", "/amcl_pose"}
        odom = [(t, m) for _, t, m in rec.messages("/odom")]
        assert len(odom) == rec.topics["/odom"].count > 100
        tf = TfBuffer.from_recording(rec)
        # odom -> base_link published on /tf agrees with the /odom message's pose at the same stamp
        stamps = tf.link_stamps("base_link")
        _, msg = odom[len(odom) // 2]
        s = time_to_ns(msg.header.stamp)
        assert msg.header.frame_id == tf.tree()["base_link"] == "odom"
        if s in set(stamps.tolist()):
            np.testing.assert_allclose(tf.lookup("odom", "base_link", s),
                                       pose_message_to_matrix(msg, "nav_msgs/msg/Odometry"), atol=1e-9)
        amcl = [m for _, _, m in rec.messages("/amcl_pose")]
        assert len(amcl) == rec.topics["/amcl_pose"].count
        assert amcl[0].header.frame_id == "map"


def test_mixed_tf_types_bag(rr):
    with open_recording(rr("watercan.bag")) as rec:
        info = rec.topics["/tf"]
        assert set(info.msgtypes) == {"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"}
        kinds = {}
        for _, mt, _, msg in rec.typed_messages("/tf"):
            kinds[mt] = kinds.get(mt, 0) + 1
        assert kinds == {"tf2_msgs/msg/TFMessage": 3199, "tf/msg/tfMessage": 333}
        assert sum(kinds.values()) == info.count
        tf = TfBuffer.from_recording(rec)
    # links that only the old tf/tfMessage carries are in the tree next to the tf2 ones
    tree = tf.tree()
    assert tree["odom_init"] == "biped_odom_particle" and tree["biped_odom_particle"] == "map"
    assert tree["pointcloud_to_scan_base"] == "BODY" and tree["CHEST_LINK0"] == "BODY"
    assert len(tf.frames()) == 84
    lo, hi = tf.time_range("map", "CHEST_LINK0")
    T = tf.lookup("map", "CHEST_LINK0", (lo + hi) // 2)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)


def test_ros2_bag_without_message_definitions(tmp_path, rr):
    """ROS 2 bags recorded before Iron carry no message definitions; standard types still decode."""
    import shutil
    import sqlite3

    folder = tmp_path / "old"
    shutil.copytree(rr("tf_example"), folder)
    for p in folder.iterdir():
        p.chmod(0o644)
    with sqlite3.connect(folder / "tf_example.db3") as db:
        db.execute("DELETE FROM message_definitions")
    with open_recording(folder) as rec, open_recording(rr("tf_example.bag")) as bag:
        assert rec.topics["/tf"].count == 517
        a, b = _tf_samples(rec), _tf_samples(bag)
    assert len(a) == 518 and all(x[:4] == y[:4] and np.array_equal(x[4], y[4]) for x, y in zip(a, b))
