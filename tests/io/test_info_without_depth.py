"""`kinfu info` on a recording without depth says what it is still good for.

Before: `kinfu info ROS_example.bag` (three PoseStamped topics) and `tf_example.bag` (TF only) listed every role as
"-" and nothing else: no word that nothing can be fused, nor that the pose topics / moving TF frames can be given
as the hand for `kinfu poi` or exported as a TUM trajectory.
"""

from kinfu_cli.io.summary import format_summary, recording_summary
from tests.recordings import make_recording


def test_tf_only_recording_names_its_moving_frames(shared_data):
    s = recording_summary(shared_data("ros-recordings", "tf_example.bag"))
    notes = s["notes"]
    assert notes[0].startswith("no depth source") and "nothing to fuse" in notes[0]
    assert "moving TF frames: base_footprint" in notes  # base_link hangs on a static link
    assert any(n.startswith("no hand detected") for n in notes)
    assert "note:           moving TF frames: base_footprint" in format_summary(s)


def test_pose_only_recording_names_its_pose_topics(shared_data):
    s = recording_summary(shared_data("ros-recordings", "ROS_example.bag"))
    assert "pose topics: ORB-SLAM, S-PTAM, groundtruth" in s["notes"]


def test_a_recording_with_depth_has_no_such_note(tmp_path):
    rec = tmp_path / "rec.mcap"
    make_recording(rec, n=3)
    s = recording_summary(rec)
    assert s["roles"]["depth_topic"] and s["notes"] == []
