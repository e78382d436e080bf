"""Hand trajectories from pose topics, TF frames and Polhemus files, checked against the raw messages."""

from __future__ import annotations

import numpy as np
import pytest
from recordings import T0, make_recording

from kinfu_cli.core.errors import RecordingError, TrajectoryError
from kinfu_cli.io.hand import load_hand_trajectory
from kinfu_cli.io.messages import pose_message_to_matrix, time_to_ns
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.tf_buffer import TfBuffer


class _Raw(list):
    """(stamp, T, frame_id) of every message of a pose topic; T built only for the samples looked at."""

    def __getitem__(self, i):
        mt, m = list.__getitem__(self, i)
        return time_to_ns(m.header.stamp), pose_message_to_matrix(m, mt), m.header.frame_id


def _raw(path, topic):
    with open_recording(path) as rec:
        return _Raw((mt, m) for _, mt, _, m in rec.typed_messages(topic))


def test_posestamped_topic_from_ros1_bag(shared_data):
    path = shared_data("ros-recordings", "ROS_example.bag")
    raw = _raw(path, "groundtruth")
    traj = load_hand_trajectory(path, hand_topic="groundtruth")
    assert len(traj) == len(raw) == 12765
    assert traj.t0_ns == raw[0][0] and traj.t[0] == 0.0 and np.all(np.diff(traj.t) > 0)
    assert traj.frame == raw[0][2]
    for i in (0, 5000, 12764):
        np.testing.assert_allclose(traj.positions[i], raw[i][1][:3, 3], atol=0)
        np.testing.assert_allclose(traj.rotations[i], raw[i][1][:3, :3], atol=1e-15)
        assert traj.t[i] == pytest.approx((raw[i][0] - raw[0][0]) * 1e-9, abs=1e-9)
    # the estimates are other topics of the same bag, with fewer samples over the same run
    slam = load_hand_trajectory(path, hand_topic="S-PTAM")
    assert len(slam) == 5439 and traj.t0_ns <= slam.t0_ns and slam.t0_ns * 1e-9 + slam.duration <= \
        traj.t0_ns * 1e-9 + traj.duration + 1.0


def test_odometry_and_amcl_from_zstd_mcap(shared_data):
    path = shared_data("ros-recordings", "nav2_turtlebot.mcap")
    odom = load_hand_trajectory(path, hand_topic="/odom")
    raw = _raw(path, "/odom")
    assert len(odom) == len(raw) == 2639 and odom.frame == "odom"
    np.testing.assert_allclose(odom.positions[1234], raw[1234][1][:3, 3], atol=0)
    # amcl poses are in map; asked for odom they go through TF map -> odom at each stamp
    amcl_raw = _raw(path, "/amcl_pose")
    amcl = load_hand_trajectory(path, hand_topic="/amcl_pose", world_frame="odom")
    assert amcl.frame == "odom" and amcl.meta["moved_from_frame"] == "map"
    assert len(amcl) + amcl.meta["outside_tf_range"] == len(amcl_raw) == 135
    with open_recording(path) as rec:
        tf = TfBuffer.from_recording(rec)
    stamp, T_map_robot, _ = amcl_raw[-1]
    expect = tf.lookup("odom", "map", stamp) @ T_map_robot
    np.testing.assert_allclose(amcl.positions[-1], expect[:3, 3], atol=1e-9)


def test_tf_frame_trajectory(shared_data):
    path = shared_data("ros-recordings", "tf_example.bag")
    traj = load_hand_trajectory(path, hand_frame="base_footprint")
    with open_recording(path) as rec:
        samples = [(time_to_ns(tr.header.stamp), tr) for _, _, m in rec.messages("/tf") for tr in m.transforms]
    assert len(traj) == len(samples) == 517 and traj.frame == "odom"
    s, tr = samples[100]
    i = int(np.argmin(np.abs(traj.t - (s - traj.t0_ns) * 1e-9)))
    np.testing.assert_allclose(traj.positions[i], [tr.transform.translation.x, tr.transform.translation.y,
                                                   tr.transform.translation.z], atol=1e-12)
    # a static child of the moving link is sampled at the moving link's stamps
    base = load_hand_trajectory(path, hand_frame="base_link")
    assert len(base) == 517 and base.t0_ns == traj.t0_ns


@pytest.mark.parametrize("name", ["h.mcap", "h.bag", "h_ros2"])
def test_detected_hand_topic_in_written_recordings(tmp_path, name):
    path = make_recording(tmp_path / name, n=3, hand=True)
    traj = load_hand_trajectory(path)
    assert traj.source.endswith(":/hand/pose") and traj.frame == "world"
    assert traj.t0_ns == T0 and len(traj) == 30  # 100 Hz over the 0.3 s of TF
    np.testing.assert_allclose(traj.t, np.arange(30) / 100, atol=1e-9)
    np.testing.assert_allclose(traj.positions[:, 0], 0.1 * np.arange(30) / 100, atol=1e-12)


def test_polhemus_dispatch(shared_data):
    from kinfu_cli.io.polhemus import read_polhemus

    path = shared_data("hand-polhemus", "pick_and_place", "user1_cup0.traj")
    a, b = load_hand_trajectory(path), read_polhemus(path)
    assert len(a) == len(b) > 100
    np.testing.assert_array_equal(a.positions, b.positions)


def test_hand_errors(tmp_path):
    path = make_recording(tmp_path / "h.mcap", n=2)
    with pytest.raises(RecordingError, match="hand topic /camera/depth/camera_info carries sensor_msgs/msg/CameraInfo"):
        load_hand_trajectory(path, hand_topic="/camera/depth/camera_info")
    with pytest.raises(RecordingError, match="hand frame 'glove' is not in the TF tree"):
        load_hand_trajectory(path, hand_frame="glove")
    with pytest.raises(RecordingError, match="no hand pose topic or TF frame found"):
        load_hand_trajectory(path)
    with pytest.raises(TrajectoryError, match="every TF link from world to base_link is static"):
        load_hand_trajectory(path, hand_frame="base_link")
