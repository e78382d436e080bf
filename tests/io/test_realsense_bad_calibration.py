"""A RealSense SDK bag whose colour calibration is damaged (colour camera info of size 0, stream extrinsics with a
NaN or zero quaternion or an offset of 1e300 m) still gives its depth frames: the colour is left out with the
reason, as for a missing calibration, and nothing reaches stderr (no traceback, no numpy warning)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.realsense_bag import sdk_summary
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter

W, H = 32, 24
K = np.array([[30.0, 0, 15.5], [0, 30.0, 11.5], [0, 0, 1]])
DEPTH = "/device_0/sensor_0/Depth_0"
COLOR = "/device_0/sensor_1/Color_0"


def _transform(w, topic, t, q):
    vec = w._type("geometry_msgs/msg/Vector3")(x=float(t[0]), y=float(t[1]), z=float(t[2]))
    quat = w._type("geometry_msgs/msg/Quaternion")(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))
    w._write(topic, "geometry_msgs/msg/Transform", 0, w._type("geometry_msgs/msg/Transform")(translation=vec,
                                                                                              rotation=quat))


def _bag(path, color_size=(W, H), color_t=(-0.015, 0.0, 0.0), color_q=(0.0, 0.0, 0.0, 1.0)):
    with RecordingWriter(path) as w:
        w.write_camera_info(f"{DEPTH}/info/camera_info", 0, "", K, W, H)
        w.write_camera_info(f"{COLOR}/info/camera_info", 0, "", K, *color_size)
        w.write_float32("/device_0/sensor_0/option/Depth Units/value", 0, 0.001)
        _transform(w, f"{DEPTH}/tf/0", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        _transform(w, f"{COLOR}/tf/0", color_t, color_q)
        for i in range(2):
            t = 1_000_000_000 + i * 33_000_000
            w.write_image(f"{DEPTH}/image/data", t, "", np.full((H, W), 800, np.uint16), "mono16")
            w.write_image(f"{COLOR}/image/data", t + 1_000_000, "", np.full((H, W, 3), 90, np.uint8), "rgb8")
    return path


@pytest.mark.parametrize("damage, reason", [
    (dict(color_size=(0, 0)), "the colour image is 0x0"),
    (dict(color_q=(np.nan, 0.0, 0.0, 1.0)), "unusable extrinsics"),
    (dict(color_q=(0.0, 0.0, 0.0, 0.0)), "unusable extrinsics"),
    (dict(color_t=(1e300, 0.0, 0.0)), "unusable extrinsics"),
])
def test_damaged_colour_calibration_costs_the_colour_only(tmp_path, damage, reason):
    path = _bag(tmp_path / "d.bag", **damage)
    stats = FrameStats()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an overflow in the extrinsics was a numpy warning on stderr
        with open_recording(path) as rec:
            frames = list(iter_frames(rec, pose_source="none", stats=stats))
            summary = sdk_summary(rec, f"{DEPTH}/image/data", f"{COLOR}/image/data")
    assert len(frames) == 2 and all(np.allclose(f.depth, 0.8) for f in frames)
    reg = summary["color_registration"]
    assert reg["mode"] == "none" and reason in reg["reason"], reg
    assert COLOR in reg["reason"] or "Color_0" in reg["reason"]


def test_depth_stream_without_camera_info_is_not_given_the_colour_cameras(tmp_path):
    """The colour stream's camera info was taken for the depth camera's (scaled to the depth image, a warning
    only): the depth intrinsics are refused as missing, naming the depth topic, and --intrinsics still reads it."""
    from click.testing import CliRunner
    from conftest import one_line_error

    from kinfu_cli.cli import cli
    from kinfu_cli.io.roles import detect_roles

    path = tmp_path / "noinfo.bag"
    with RecordingWriter(path) as w:
        w.write_camera_info(f"{COLOR}/info/camera_info", 0, "", K * [[2], [2], [1]], 2 * W, 2 * H)
        for i in range(2):
            t = 1_000_000_000 + i * 33_000_000
            w.write_image(f"{DEPTH}/image/data", t, "", np.full((H, W), 800, np.uint16), "mono16")
            w.write_image(f"{COLOR}/image/data", t + 1_000_000, "", np.full((2 * H, 2 * W, 3), 90, np.uint8), "rgb8")
    with open_recording(path) as rec:
        assert detect_roles(rec).info_topic is None
    one_line_error(CliRunner().invoke(cli, ["export", str(path), "-o", str(tmp_path / "e"), "-q", "--pose-source",
                                            "none"]), "--intrinsics", f"{DEPTH}/image/data")
    res = CliRunner().invoke(cli, ["export", str(path), "-o", str(tmp_path / "e"), "-q", "--pose-source", "none",
                                   "--intrinsics", "30,30,15.5,11.5"])
    assert res.exit_code == 0 and (tmp_path / "e" / "frame-000001.depth.png").exists(), res.output


@pytest.mark.parametrize("msgtype, value, ok", [("std_msgs/msg/String", "abc", False),
                                                ("std_msgs/msg/String", "0.0001", True),
                                                ("std_msgs/msg/Float64", 0.0001, True)])
def test_depth_units_of_another_message_type(tmp_path, msgtype, value, ok):
    """A Depth Units option recorded as text crashed with "ValueError: could not convert string to float"."""
    from kinfu_cli.core.errors import RecordingError

    path = tmp_path / "u.bag"
    topic = "/device_0/sensor_0/option/Depth Units/value"
    with RecordingWriter(path) as w:
        w.write_camera_info(f"{DEPTH}/info/camera_info", 0, "", K, W, H)
        w._write(topic, msgtype, 0, w._type(msgtype)(data=value))
        w.write_image(f"{DEPTH}/image/data", 1_000_000_000, "", np.full((H, W), 8000, np.uint16), "mono16")
    with open_recording(path) as rec:
        if ok:
            frames = list(iter_frames(rec, pose_source="none"))
            assert np.allclose(frames[0].depth, 0.8)
        else:
            with pytest.raises(RecordingError, match="depth units 'abc' is no number") as info:
                list(iter_frames(rec, pose_source="none"))
            assert topic in str(info.value)
