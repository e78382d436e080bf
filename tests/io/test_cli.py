"""`kinfu info` on real and written recordings, and one-line errors for bad input."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error
from recordings import make_recording

from kinfu_cli.core.ownership import MANIFEST
from kinfu_cli.cli import cli


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.mark.parametrize("name,topics,frames", [
    ("tf_example.bag", {"/tf": 517, "/tf_static": 1}, 3),
    ("tf_example", {"/tf": 517, "/tf_static": 1}, 3),
    ("ROS_example.bag", {"groundtruth": 12765, "ORB-SLAM": 8362, "S-PTAM": 5439}, 0),
    ("nav2_turtlebot.mcap", {"/tf": 5422, "/tf_static": 1, "/odom": 2639, "/amcl_pose": 135}, 34),
    ("watercan.bag", {"/tf": 3532, "/euclidean_cluster_indices_decomposer/output00": 1}, 84),
])
def test_info_json_on_real_recordings(shared_data, name, topics, frames):
    res = run("info", shared_data("ros-recordings", name), "--json")
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert {t["name"]: t["count"] for t in s["topics"]} == topics
    assert s["message_count"] == sum(topics.values())
    assert len(s["tf"]["frames"]) == frames
    assert s["storage"] == ("sqlite3" if name == "tf_example" else None)
    if name.startswith("tf_example"):
        assert s["tf"]["tree"] == {"base_footprint": "odom", "base_link": "base_footprint"}
        assert s["roles"]["world_frame"] == "odom"
        assert 51.6 < s["duration_s"] < 51.7
        link = next(l for l in s["tf"]["links"] if l["child"] == "base_footprint")
        assert link["samples"] == 517 and not link["static"] and abs(link["rate_hz"] - 10.0) < 0.05
    if name == "nav2_turtlebot.mcap":
        assert s["format"] == "mcap" and s["tf"]["tree"]["odom"] == "map" and s["roles"]["world_frame"] == "map"
    if name == "watercan.bag":
        tf = next(t for t in s["topics"] if t["name"] == "/tf")
        assert set(tf["msgtypes"]) == {"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"}


def test_info_text_on_written_recording(tmp_path):
    path = make_recording(tmp_path / "r.mcap", n=4, hand=True)
    res = run("info", path)
    assert res.exit_code == 0, res.output
    out = res.output
    assert "/camera/depth/image_raw" in out and "sensor_msgs/msg/Image" in out
    assert "depth topic:    /camera/depth/image_raw" in out
    assert "camera frame:   camera_optical" in out and "world frame:    world" in out
    assert "hand topic:     /hand/pose" in out
    # the tree: world -> base_link -> wrist -> camera_optical, indented by depth
    assert "\n  world\n    base_link  (static)\n      wrist  (" in out
    assert "        camera_optical  (static)" in out
    # an override wins
    res = run("info", path, "--json", "--world-frame", "base_link", "--info-topic", "/camera/depth/camera_info")
    roles = json.loads(res.output)["roles"]
    assert roles["world_frame"] == "base_link" and roles["info_topic"] == "/camera/depth/camera_info"
    # the depth topic named as the colour topic is refused (fuse went on to "no depth frames in the selection")
    res = run("info", path, "--color-topic", "/camera/depth/image_raw")
    assert res.exit_code == 2 and res.output.startswith("kinfu: error: --color-topic:") and "depth topic" in res.output


def test_info_bad_input(tmp_path, shared_data):
    empty = tmp_path / "empty.bag"
    empty.write_bytes(b"")
    one_line_error(run("info", empty), "empty.bag", "empty file", "expected")
    text = tmp_path / "notes.bag"
    text.write_text("not a bag\n")
    one_line_error(run("info", text), "notes.bag", "not a recording")
    src = shared_data("ros-recordings", "tf_example.bag")
    trunc = tmp_path / "cut.bag"
    trunc.write_bytes(src.read_bytes()[:20000])
    one_line_error(run("info", trunc), "cut.bag", "truncated")
    mcap = shared_data("ros-recordings", "nav2_turtlebot.mcap")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    # one zstd chunk holds everything: cut in half, nothing whole is left (io/mcap_truncated.py reads what is)
    one_line_error(run("info", cut), "cut.mcap", "truncated", "nothing whole to read")
    folder = tmp_path / "folder"
    folder.mkdir()
    one_line_error(run("info", folder), "folder", "metadata.yaml")
    one_line_error(run("info", tmp_path / "missing.mcap"), "missing.mcap", "no such file")
    ros2 = tmp_path / "ros2"
    shutil.copytree(shared_data("ros-recordings", "tf_example"), ros2)
    db = ros2 / "tf_example.db3"
    db.chmod(0o644)
    db.write_bytes(db.read_bytes()[:30000])
    one_line_error(run("info", ros2), "ros2", "ROS 2 bag")
    good = make_recording(tmp_path / "ok.bag", n=2)
    line = one_line_error(run("info", good, "--depth-topic", "/camera/depth"), "ok.bag", "'/camera/depth' not found")
    assert "/camera/depth/image_raw" in line  # lists what is there


def test_export_then_import_round_trip(tmp_path, sample_dir):
    out = tmp_path / "frames"
    res = run("export", sample_dir / "recording.bag", "-o", out, "--json", "-q")
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert s["frames"] == 36 and s["stats"]["dropped_total"] == 0
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != MANIFEST) == ["frames"]
    res = run("import", out, "-o", tmp_path / "again.mcap", "--rate", "5", "-q")
    assert res.exit_code == 0, res.output
    from kinfu_cli.io.frames import iter_frames
    from kinfu_cli.io.recording import open_recording

    with open_recording(sample_dir / "recording.bag") as a, open_recording(tmp_path / "again.mcap") as b:
        fa, fb = list(iter_frames(a)), list(iter_frames(b))
    assert len(fa) == len(fb) == 36
    for x, y in zip(fa, fb):
        np.testing.assert_array_equal(x.depth, y.depth)  # mm survive float32 metres -> PNG -> recording
        np.testing.assert_array_equal(x.color, y.color)
        np.testing.assert_array_equal(x.K, y.K)
        np.testing.assert_allclose(x.T_world_camera, y.T_world_camera, atol=1e-12)


def test_frame_errors_through_the_cli(tmp_path, shared_data):
    good = make_recording(tmp_path / "good.mcap", n=2)
    out = tmp_path / "out"
    one_line_error(run("export", good, "-o", out, "--depth-topic", "/camera/depth/missing"),
                   "good.mcap", "depth topic '/camera/depth/missing' not found", "/camera/depth/image_raw")
    one_line_error(run("export", shared_data("ros-recordings", "tf_example.bag"), "-o", out),
                   "tf_example.bag", "no depth image topic found", "--depth-topic")
    one_line_error(run("export", make_recording(tmp_path / "enc.bag", n=2, depth_encoding="mono8"), "-o", out,
                       "--depth-topic", "/camera/depth/image_raw"),
                   "/camera/depth/image_raw", "depth encoding 'mono8' is not supported")
    one_line_error(run("export", good, "-o", out, "--camera-frame", "camera_ir"),
                   "camera_ir", "world", "not in the TF tree")
    one_line_error(run("export", good, "-o", out, "--world-frame", "map"), "map", "camera_optical")
    one_line_error(run("export", make_recording(tmp_path / "noinfo_ros2", n=2, info=False), "-o", out),
                   "noinfo_ros2", "no sensor_msgs/CameraInfo topic", "/camera/depth/image_raw")
    # TF starts after every frame: nothing to export is an error too, and names why
    late = make_recording(tmp_path / "late.bag", n=3, tf_from=5.0)
    one_line_error(run("export", late, "-o", out, "--tolerance", "0.01"), "late.bag", "no usable depth frame",
                   "no camera pose")
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".") and p.name != MANIFEST]  # no temp folders either


def test_info_frames_reports_dropped_frames(tmp_path):
    path = make_recording(tmp_path / "late.mcap", n=15, tf_from=0.2)
    res = run("info", path, "--frames", "--tolerance", "0.005", "--json")
    assert res.exit_code == 0, res.output
    fr = json.loads(res.output)["frames"]
    assert fr["depth_messages"] == 15 and fr["used"] == 10
    assert fr["dropped"] == {"no camera pose within the TF range": 5}
    res = run("info", path, "--frames", "--tolerance", "0.005", "--every", "3")
    assert "RGB-D frames: 3 usable of 15 depth messages (skipped 10, without colour 0)" in res.output
    assert "dropped 2: no camera pose within the TF range" in res.output
