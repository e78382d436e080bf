"""`kinfu info --frames` says what fuse and export say about the frames: before, a recording whose depth was logged
1.1 s late printed only "without colour 40" (and color_cut_short: 40 in the JSON), none of the warnings."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.writers import RecordingWriter

T0 = 1_700_000_000 * 10**9
PERIOD = 33_333_333
W, H = 8, 6
K = np.array([[10.0, 0, 3.5], [0, 10.0, 2.5], [0, 0, 1]])


def _depth_logged_late(path, latency_ns=1_100_000_000, n=90):
    """Colour at 30 Hz logged at its stamp; depth at every third colour stamp, logged latency_ns late."""
    events = [(T0 + k * PERIOD, "colour", k) for k in range(n)]
    events += [(T0 + k * PERIOD + latency_ns, "depth", k) for k in range(0, n, 3)]
    with RecordingWriter(path) as w:
        for log_ns, kind, k in sorted(events):
            stamp = T0 + k * PERIOD
            if kind == "colour":
                img = np.full((H, W, 3), [k % 256, 200, 7], np.uint8)
                msg = w._type("sensor_msgs/msg/Image")(
                    header=w._header("/camera/color/image_raw", stamp, "cam"), height=H, width=W, encoding="rgb8",
                    is_bigendian=0, step=W * 3, data=np.frombuffer(img.tobytes(), np.uint8))
                w._write("/camera/color/image_raw", "sensor_msgs/msg/Image", log_ns, msg)
                continue
            depth = np.full((H, W), 1000 + k, np.uint16)
            msg = w._type("sensor_msgs/msg/Image")(
                header=w._header("/camera/depth/image_raw", stamp, "cam"), height=H, width=W, encoding="16UC1",
                is_bigendian=0, step=W * 2, data=np.frombuffer(depth.tobytes(), np.uint8))
            w._write("/camera/depth/image_raw", "sensor_msgs/msg/Image", log_ns, msg)
            write = w._write
            w._write = lambda topic, msgtype, _, m, trailer=b"": write(topic, msgtype, log_ns, m, trailer)
            w.write_camera_info("/camera/depth/camera_info", stamp, "cam", K, W, H)
            w._write = write
    return path


def _warnings(res) -> list[str]:
    return [line for line in res.stderr.splitlines() if line.startswith("kinfu: warning: ")]


def test_info_frames_prints_the_frame_warnings(tmp_path):
    path = _depth_logged_late(tmp_path / "late.mcap")
    res = CliRunner().invoke(cli, ["info", str(path), "--frames", "-q", "--pose-source", "none"])
    assert res.exit_code == 0, res.output
    said = _warnings(res)
    assert any("frames have no colour" in w for w in said), res.stderr
    assert any("no longer kept" in w for w in said), res.stderr
    assert len(res.stderr.splitlines()) == len(said)  # nothing else on stderr

    res = CliRunner().invoke(cli, ["info", str(path), "--frames", "-q", "--pose-source", "none", "--json"])
    doc = json.loads(res.stdout)
    assert doc["frames"]["color_cut_short"] > 0 and len(doc["warnings"]) == len(said) == len(_warnings(res))


def test_info_without_frames_prints_no_frame_warnings(tmp_path):
    res = CliRunner().invoke(cli, ["info", str(_depth_logged_late(tmp_path / "late.mcap"))])
    assert res.exit_code == 0, res.output
    assert not _warnings(res)
