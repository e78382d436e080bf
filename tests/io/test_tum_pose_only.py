"""`kinfu export --trajectory tum` of a recording with poses but no depth (evo's test bags, a robot's odometry):
the pose stream at its own samples.

Before: `kinfu export ROS_example.bag --trajectory tum --pose-source topic --pose-topic groundtruth` and
`kinfu export tf_example.bag --trajectory tum --camera-frame base_link` failed with "no depth image topic
found": a pose-only recording could not be turned into the TUM file evo reads.
"""

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.tum import read_tum, recording_trajectory


def test_tf_link_at_its_own_stamps(shared_data):
    bag = shared_data("ros-recordings", "tf_example.bag")
    stamps, T, info = recording_trajectory(bag, {"camera_frame": "base_link"}, pose_source="tf")
    assert len(stamps) == 517 and info["world_frame"] == "odom" and "no depth topic" in info["sampled_at"]
    assert np.all(np.diff(stamps) > 0)
    assert np.allclose(np.diff(stamps).mean() * 1e-9, 0.1, atol=0.005)  # the 10 Hz odometry link
    assert np.allclose(np.einsum("nij,nkj->nik", T[:, :3, :3], T[:, :3, :3]), np.eye(3), atol=1e-9)
    _, T5, _ = recording_trajectory(bag, {"camera_frame": "base_link"}, pose_source="tf", every=5, start_s=10.0)
    assert 80 <= len(T5) <= 86  # the 417 samples after 10 s, every 5th
    with pytest.raises(Exception, match="camera frame"):
        recording_trajectory(bag, {}, pose_source="tf")


def test_cli_writes_the_pose_topic_as_tum(shared_data, tmp_path):
    bag = shared_data("ros-recordings", "ROS_example.bag")
    out = tmp_path / "gt.tum"
    res = CliRunner().invoke(cli, ["export", str(bag), "--trajectory", "tum", "--pose-source", "topic",
                                   "--pose-topic", "groundtruth", "--end", "60", "-o", str(out)])
    assert res.exit_code == 0, res.output
    stamps, T = read_tum(out)
    assert 300 < len(stamps) < 12765 / 10 and (stamps[-1] - stamps[0]) * 1e-9 <= 60.0  # the first 60 s only
    assert stamps[0] == 1502792570283404827  # the first groundtruth message's header stamp
    assert "samples of pose topic groundtruth" in out.read_text().splitlines()[1]
