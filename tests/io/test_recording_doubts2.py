"""Doubtful recordings said, not read silently: truncated MCAP files, repeated depth stamps, a hand topic changing
frame, 32FC1 depth in millimetres, wrong metadata.yaml counts, one corrupt /tf message."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.writer import Writer as McapWriter
from rosbags.typesys import Stores, get_typestore

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import RecordingError, TrajectoryError
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.hand import load_hand_trajectory
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter
from tests.conftest import one_line_error
from tests.recordings import K, T0, T_WORLD_BASE, S, make_recording

W, H = 5, 4


def _image(w: RecordingWriter, topic: str, log_ns: int, stamp_ns: int, depth: np.ndarray, encoding="16UC1"):
    """A depth image whose header stamp is not its log time (write_image gives both the one stamp)."""
    data = np.ascontiguousarray(depth)
    msg = w._type("sensor_msgs/msg/Image")(
        header=w._header(topic, stamp_ns, "cam"), height=data.shape[0], width=data.shape[1], encoding=encoding,
        is_bigendian=0, step=data.shape[1] * data.itemsize, data=np.frombuffer(data.tobytes(), np.uint8))
    w._write(topic, "sensor_msgs/msg/Image", log_ns, msg)


# ------------------------------------------------------------------------------- 1, 2: truncated MCAP files
def _late_depth_mcap(path):
    """An MCAP file of small chunks: 50 /tf messages, then the depth topic's first channel and messages."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with path.open("wb") as f:
        w = McapWriter(f, chunk_size=2000)
        w.start("ros2", "kinfu-test")
        tf_schema = w.register_schema("tf2_msgs/msg/TFMessage", "ros2msg",
                                      ts.generate_msgdef("tf2_msgs/msg/TFMessage", ros_version=2)[0].encode())
        tf_channel = w.register_channel("/tf", "cdr", tf_schema)
        T = ts.types
        for k in range(50):
            st = T0 + k * 10**7
            tr = T["geometry_msgs/msg/TransformStamped"](
                header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=st // S, nanosec=st % S),
                                                frame_id="world"), child_frame_id="cam",
                transform=T["geometry_msgs/msg/Transform"](
                    translation=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                    rotation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
            msg = T["tf2_msgs/msg/TFMessage"](transforms=[tr])
            w.add_message(tf_channel, st, bytes(ts.serialize_cdr(msg, "tf2_msgs/msg/TFMessage")), st)
        cut_at = f.tell()
        im_schema = w.register_schema("sensor_msgs/msg/Image", "ros2msg",
                                      ts.generate_msgdef("sensor_msgs/msg/Image", ros_version=2)[0].encode())
        im_channel = w.register_channel("/depth", "cdr", im_schema)
        for i in range(5):
            st = T0 + S + i * S // 30
            msg = T["sensor_msgs/msg/Image"](
                header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=st // S, nanosec=st % S),
                                                frame_id="cam"), height=H, width=W, encoding="16UC1",
                is_bigendian=0, step=2 * W, data=np.full(H * W * 2, 3, np.uint8))
            w.add_message(im_channel, st, bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/Image")), st)
        w.finish()
    return cut_at


def test_a_topic_lost_in_the_cut_part_is_said_to_be_lost_there(tmp_path):
    whole = tmp_path / "whole.mcap"
    cut_at = _late_depth_mcap(whole)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[: cut_at + 400])
    runner = CliRunner()
    for args in (["--depth-topic", "/depth"], []):
        res = runner.invoke(cli, ["export", str(cut), "-o", str(tmp_path / "out"), "--intrinsics", "5,5,2,1.5",
                                  "--pose-source", "none", *args])
        line = one_line_error(res, "cut.mcap", "truncated", f"of {cut_at + 400} bytes")
        assert "/tf" in line  # what could be read is still listed


@pytest.mark.parametrize("size", [3, 8, 12])
def test_an_mcap_cut_within_its_first_bytes_is_one_error_line(sample_dir, tmp_path, size):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes((sample_dir / "recording.mcap").read_bytes()[:size])
    runner = CliRunner()
    for args in (["info", str(cut)], ["fuse", str(cut), "-o", str(tmp_path / "out")]):
        line = one_line_error(runner.invoke(cli, args), "cut.mcap", "truncated", "not a complete MCAP")
        assert "ord()" not in line


# ------------------------------------------------------------------------------- 3: depth stamps not increasing
def test_repeated_and_backward_depth_stamps_are_counted_in_a_warning(tmp_path):
    path = tmp_path / "stamps.mcap"
    headers = [0, 33, 33, 20, 66, 100]  # ms: one repeated, one backwards
    with RecordingWriter(path) as w:
        for i, ms in enumerate(headers):
            log = T0 + i * 40_000_000
            w.write_camera_info("/depth/camera_info", log, "cam", K, W, H)
            _image(w, "/depth/image", log, T0 + ms * 1_000_000, np.full((H, W), 900 + i, np.uint16))
    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, pose_source="none", stats=stats, tolerance_s=0.0))
        warnings = stats.warnings(str(rec.path))
    assert len(frames) == len(headers)  # kept: there is no rule to drop them
    assert stats.stamps_not_increasing == 2 and stats.as_dict()["stamps_not_increasing"] == 2
    said = [w for w in warnings if "earlier than the one before" in w]
    assert len(said) == 1 and "2 of 6 depth images" in said[0] and str(T0 + 33_000_000) in said[0]


def test_increasing_depth_stamps_say_nothing(tmp_path):
    path = make_recording(tmp_path / "ok.mcap", n=4)
    stats = FrameStats()
    with open_recording(path) as rec:
        list(iter_frames(rec, stats=stats))
        assert stats.stamps_not_increasing == 0
        assert not [w for w in stats.warnings(str(rec.path)) if "earlier" in w]


# ------------------------------------------------------------------------------- 4: hand topic changing frame
def _hand_in_two_frames(path, second: str):
    """/hand/pose at one place in world: the first 10 samples in world, then in `second` (base_link is linked
    to world by a static TF, so the same place)."""
    with RecordingWriter(path) as w:
        w.write_tf(T0, [("world", "base_link", T_WORLD_BASE)], static=True)
        for k in range(20):
            T = np.eye(4)
            T[:3, 3] = [0.1, 0.2, 0.3]
            frame = "world" if k < 10 else second
            w.write_pose("/hand/pose", T0 + k * S // 10, frame, np.linalg.inv(T_WORLD_BASE) @ T if k >= 10 else T)
    return path


def test_hand_poses_in_two_linked_frames_are_moved_into_one_and_said(tmp_path):
    traj = load_hand_trajectory(_hand_in_two_frames(tmp_path / "two.mcap", "base_link"))
    assert traj.frame == "world"
    np.testing.assert_allclose(traj.positions, np.tile([0.1, 0.2, 0.3], (20, 1)), atol=1e-9)  # not 0.7 m apart
    said = [p for p in traj.meta["recording_problems"] if "changes frame_id" in p]
    assert len(said) == 1 and "/hand/pose" in said[0] and "'world'" in said[0] and "'base_link'" in said[0]
    assert "10 samples" in said[0]


def test_hand_poses_in_two_unlinked_frames_are_an_error(tmp_path):
    with pytest.raises(TrajectoryError, match=r"/hand/pose changes frame_id from 'world' to 'nowhere'.*no TF chain"):
        load_hand_trajectory(_hand_in_two_frames(tmp_path / "two.mcap", "nowhere"))


# ------------------------------------------------------------------------------- 5: 32FC1 depth in millimetres
def test_export_of_32fc1_millimetres_warns_with_the_pixel_count(tmp_path):
    path = tmp_path / "mm.mcap"
    depth = np.full((H, W), 850.0, np.float32)  # mm written as if metres
    depth[0, 0] = 0.0
    depth[0, 1] = 0.8  # one plausible pixel
    with RecordingWriter(path) as w:
        for i in range(3):
            w.write_camera_info("/depth/camera_info", T0 + i * S // 30, "cam", K, W, H)
            w.write_image("/depth/image", T0 + i * S // 30, "cam", depth, "32FC1")
    out = tmp_path / "frames"
    res = CliRunner().invoke(cli, ["export", str(path), "-o", str(out), "--pose-source", "none", "--quiet"])
    assert res.exit_code == 0, res.output
    warnings = [l for l in res.output.splitlines() if l.startswith("kinfu: warning:") and "65.535 m" in l]
    assert len(warnings) == 1 and f"{3 * (H * W - 2)} depth pixels in 3 frames" in warnings[0]
    doc = json.loads((out / "frames.json").read_text())
    assert any("65.535 m" in w for w in doc["warnings"])
    assert doc["stats"]["pixels_over_16bit_mm"] == 3 * (H * W - 2)


# ------------------------------------------------------------------------------- 6: metadata.yaml counts
def test_ros2_counts_come_from_the_storage_not_metadata_yaml(sample_dir, tmp_path):
    bag = tmp_path / "bag"
    shutil.copytree(sample_dir / "recording_ros2", bag)
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("message_count: 495", "message_count: 7"))
    with open_recording(bag) as rec:
        assert rec.topics["/hand/pose"].count == 495 == sum(1 for _ in rec.messages(["/hand/pose"]))
        said = [p for p in rec.problems if "metadata.yaml" in p]
        assert len(said) == 1 and "/hand/pose 7 listed, 495 stored" in said[0]
    res = CliRunner().invoke(cli, ["info", str(bag), "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert {t["name"]: t["count"] for t in doc["topics"]}["/hand/pose"] == 495
    with open_recording(sample_dir / "recording_ros2") as rec:
        assert not rec.problems


# ------------------------------------------------------------------------------- 7: a corrupt /tf message
def _corrupt_tf_recording(path, corrupt: set[int], n_tf=60):
    """An arm-camera-like recording with /hand/pose and /tf, the /tf messages numbered in `corrupt` garbage."""
    with RecordingWriter(path) as w:
        w.write_tf(T0, [("world", "base_link", T_WORLD_BASE)], static=True)
        for k in range(n_tf):
            stamp = T0 + k * S // 20
            if k in corrupt:  # bytes that no TFMessage decodes from
                w._writer.write(w._conn("/tf", "tf2_msgs/msg/TFMessage"), stamp, b"\xff\xfe\x01garbage")
            else:
                T = np.eye(4)
                T[:3, 3] = [0.01 * k, 0.0, 0.0]
                w.write_tf(stamp, [("base_link", "wrist", T)])
            T = np.eye(4)
            T[:3, 3] = [0.3 + 0.2 * np.sin(k / 5), 0.1, 0.2]
            w.write_pose("/hand/pose", stamp, "world", T)
    return path


@pytest.mark.parametrize("suffix", [".mcap", ".bag", ".ros1.mcap"])
def test_one_corrupt_tf_message_is_skipped_and_counted(tmp_path, suffix):
    path = _corrupt_tf_recording(tmp_path / ("bad.mcap" if suffix == ".mcap" else "bad.bag"), corrupt={7})
    if suffix == ".ros1.mcap":  # read by the mcap library's ROS 1 decoder
        from tests.io.test_mcap_ros1 import bag_to_ros1_mcap

        path = bag_to_ros1_mcap(path, tmp_path / "bad.ros1.mcap")
    res = CliRunner().invoke(cli, ["poi", str(path), "-o", str(tmp_path / "pois.json"), "--min-task", "0.1",
                                   "--quiet"])
    assert res.exit_code == 0, res.output
    said = [l for l in res.output.splitlines() if l.startswith("kinfu: warning:") and "corrupt" in l]
    assert len(said) == 1 and "/tf" in said[0] and "skipped 1 corrupt message of 60" in said[0]
    with open_recording(path) as rec:
        from kinfu_cli.io.tf_buffer import TfBuffer

        tf = TfBuffer.from_recording(rec)
        TfBuffer.from_recording(rec)  # read twice: said once
        assert tf.link_stamps("wrist").size == 59
        assert len([p for p in rec.problems if "corrupt" in p]) == 1


def test_mostly_corrupt_tf_is_an_error(tmp_path):
    path = _corrupt_tf_recording(tmp_path / "bad.mcap", corrupt=set(range(0, 60, 2)) | {1})
    res = CliRunner().invoke(cli, ["info", str(path)])
    one_line_error(res, "bad.mcap", "/tf", "31 of the 60 messages")


def test_a_corrupt_message_of_another_topic_stays_an_error(tmp_path):
    path = tmp_path / "bad.mcap"
    with RecordingWriter(path) as w:
        w.write_pose("/hand/pose", T0, "world", np.eye(4))
        w._writer.write(w._conn("/hand/pose", "geometry_msgs/msg/PoseStamped"), T0 + 1, b"\xff\xfe")
    with open_recording(path) as rec:
        with pytest.raises(RecordingError, match="/hand/pose: cannot decode"):
            list(rec.messages(["/hand/pose"]))
