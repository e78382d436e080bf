"""RecordingWriter: every container round-trips images, intrinsics, TF and poses bit-exactly; failures leave nothing."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation

from kinfu_cli.core.ownership import MANIFEST
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.messages import (camera_info_K, decode_color, decode_depth, header_frame, header_stamp_ns,
                                   pose_message_to_matrix, transform_to_matrix)
from kinfu_cli.io.writers import RecordingWriter, format_for

RNG = np.random.default_rng(7)
DEPTH_MM = RNG.integers(0, 6000, (24, 32)).astype(np.uint16)
_YY, _XX = np.mgrid[0:24, 0:32]
RGB = np.dstack([_XX * 8, _YY * 10, np.full_like(_XX, 200)]).astype(np.uint8)  # smooth: JPEG keeps it close
K = np.array([[40.0, 0, 15.5], [0, 41.0, 11.5], [0, 0, 1]])


def _pose(i: int) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.1 * i, -0.2, 0.3 + 0.05 * i]).as_matrix()
    T[:3, 3] = [0.5 * i, -1.0, 2.0 + i]
    return T


def _write(path, n=3, fmt=None, compression=None):
    stamps = [1_700_000_000_000_000_000 + i * 33_333_333 for i in range(n)]
    with RecordingWriter(path, fmt=fmt, compression=compression) as w:
        w.write_tf(stamps[0], [("wrist", "camera_optical", _pose(9))], static=True)
        for i, t in enumerate(stamps):
            w.write_image("/depth", t, "camera_optical", DEPTH_MM + i, "16UC1")
            w.write_image("/depth32", t, "camera_optical", (DEPTH_MM + i) / 1000.0, "32FC1")
            w.write_compressed_depth("/depth_c", t, "camera_optical", DEPTH_MM + i)
            for enc in ("rgb8", "bgr8", "rgba8", "bgra8", "mono8"):
                arr = {"rgb8": RGB, "bgr8": RGB[:, :, ::-1], "mono8": RGB[:, :, 0],
                       "rgba8": np.dstack([RGB, np.full(RGB.shape[:2], 255, np.uint8)]),
                       "bgra8": np.dstack([RGB[:, :, ::-1], np.zeros(RGB.shape[:2], np.uint8)])}[enc]
                w.write_image(f"/color_{enc}", t, "camera_optical", arr, enc)
            w.write_compressed_image("/color_png", t, "camera_optical", RGB, "png")
            w.write_compressed_image("/color_jpeg", t, "camera_optical", RGB, "jpeg")
            w.write_camera_info("/info", t, "camera_optical", K, 32, 24)
            w.write_tf(t, [("world", "base_link", _pose(i)), ("base_link", "wrist", _pose(i + 1))])
            w.write_pose("/hand/pose", t, "world", _pose(i + 2))
    return stamps


@pytest.mark.parametrize("name,fmt,compression", [
    ("rec.mcap", None, None), ("rec.bag", None, None), ("rec_ros2", None, None),
    ("rec_mcap_folder", "ros2-mcap", None), ("z.mcap", None, "zstd"), ("z.bag", None, "lz4"),
    ("z_ros2", None, "zstd"), ("z_mcap_folder", "ros2-mcap", "zstd")])
def test_round_trip_is_exact(tmp_path, name, fmt, compression):
    path = tmp_path / name
    stamps = _write(path, fmt=fmt, compression=compression)
    assert [p.name for p in tmp_path.iterdir() if p.name != MANIFEST] == [name]  # no temp files left behind
    seen: dict[str, int] = {}
    with AnyReader([path]) as reader:
        for conn, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            topic = conn.topic
            i = seen.get(topic, 0)
            seen[topic] = i + 1
            if topic != "/tf_static":
                assert log_ns == stamps[i]
            if hasattr(msg, "header"):
                assert header_stamp_ns(msg) == stamps[i]
            if topic == "/depth" or topic == "/depth_c":
                np.testing.assert_array_equal(decode_depth(msg), (DEPTH_MM + i).astype(np.float32) * np.float32(0.001))
                assert header_frame(msg) == "camera_optical"
            elif topic == "/depth32":
                np.testing.assert_array_equal(decode_depth(msg), ((DEPTH_MM + i) / 1000.0).astype(np.float32))
            elif topic == "/color_mono8":
                np.testing.assert_array_equal(decode_color(msg), np.repeat(RGB[:, :, :1], 3, axis=2))
            elif topic.startswith("/color_") and topic != "/color_jpeg":
                np.testing.assert_array_equal(decode_color(msg), RGB)
            elif topic == "/color_jpeg":
                got = decode_color(msg).astype(int)
                assert np.abs(got - RGB).mean() < 4  # lossy, but the same image in RGB order
                assert np.abs(got - RGB[:, :, ::-1]).mean() > 40
            elif topic == "/info":
                Kr, w, h = camera_info_K(msg)
                np.testing.assert_array_equal(Kr, K)
                assert (w, h) == (32, 24)
            elif topic == "/tf":
                got = {(x.header.frame_id, x.child_frame_id): transform_to_matrix(x.transform) for x in msg.transforms}
                np.testing.assert_allclose(got[("world", "base_link")], _pose(i), atol=1e-12)
                np.testing.assert_allclose(got[("base_link", "wrist")], _pose(i + 1), atol=1e-12)
            elif topic == "/tf_static":
                np.testing.assert_allclose(transform_to_matrix(msg.transforms[0].transform), _pose(9), atol=1e-12)
            elif topic == "/hand/pose":
                np.testing.assert_allclose(pose_message_to_matrix(msg, conn.msgtype), _pose(i + 2), atol=1e-12)
    assert seen["/depth"] == 3 and seen["/tf"] == 3 and seen["/tf_static"] == 1 and seen["/hand/pose"] == 3
    assert len(seen) == 14


@pytest.mark.parametrize("name", ["bad.mcap", "bad.bag", "bad_ros2"])
def test_failed_write_leaves_no_output(tmp_path, name):
    with pytest.raises(RuntimeError):
        with RecordingWriter(tmp_path / name) as w:
            w.write_image("/depth", 1, "cam", DEPTH_MM, "16UC1")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_bad_arguments_raise_config_errors(tmp_path):
    assert format_for("x.mcap") == "mcap" and format_for("x.bag") == "bag" and format_for("x") == "ros2"
    with pytest.raises(ConfigError, match="encoding"):
        with RecordingWriter(tmp_path / "a.mcap") as w:
            w.write_image("/d", 1, "cam", DEPTH_MM, "yuv422")
    with pytest.raises(ConfigError, match="shape"):
        with RecordingWriter(tmp_path / "b.mcap") as w:
            w.write_image("/c", 1, "cam", DEPTH_MM, "rgb8")
    with pytest.raises(ConfigError, match="4x4"):
        with RecordingWriter(tmp_path / "c.bag") as w:
            w.write_pose("/p", 1, "world", np.eye(3))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name, fmt", [("results.json", None), ("depth.png", None), ("x.mcap", "ros2"),
                                       ("x.bag", "ros2-mcap"), ("notes.txt", None)])
def test_ros2_folder_named_like_a_file_is_refused(tmp_path, name, fmt):
    # the library, not only the commands: a ROS 2 bag folder called results.json is a mistake nobody asked for
    with pytest.raises(ConfigError, match="a ROS 2 bag is a folder"):
        RecordingWriter(tmp_path / name, fmt=fmt)
    assert list(tmp_path.iterdir()) == []
    assert format_for("run.2026-11-29") == "ros2" and format_for("x.db3.d") == "ros2"
