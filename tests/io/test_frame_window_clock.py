"""--start / --end select frames by the recording's time (log time), whatever clock the headers use.

Real recordings often stamp images with another clock than the recorder's: a RealSense SDK bag stamps them
with the device's clock while its message times start near zero; simulated time; a driver without time sync.
The window used to be compared with the header stamps, so such a recording gave no frame at all."""

from __future__ import annotations

import numpy as np

from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter

DEVICE_LAG_NS = 1000 * 10 ** 9  # the headers' clock is 1000 s behind the recorder's
T0 = 1_700_000_000 * 10 ** 9


def _recording(path, fmt):
    K = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]])
    with RecordingWriter(path, fmt=fmt) as w:
        write = w._write  # log time = header stamp + the lag: the recorder's clock, not the device's
        w._write = lambda topic, msgtype, stamp, msg, trailer=b"": write(topic, msgtype, stamp + DEVICE_LAG_NS,
                                                                          msg, trailer)
        for k in range(10):  # 10 Hz
            stamp = T0 - DEVICE_LAG_NS + k * 100_000_000
            w.write_camera_info("/camera/depth/camera_info", stamp, "camera_depth_optical_frame", K, 64, 48)
            w.write_image("/camera/depth/image_raw", stamp, "camera_depth_optical_frame",
                          np.full((48, 64), 1000 + k, np.uint16), "16UC1")
    return path


def test_time_window_uses_the_recording_clock(tmp_path):
    for fmt, name in (("mcap", "r.mcap"), ("bag", "r.bag")):
        with open_recording(_recording(tmp_path / name, fmt)) as rec:
            stats = FrameStats()
            frames = list(iter_frames(rec, pose_source="none", start_s=0.25, end_s=0.65, stats=stats))
            assert [round(float(f.depth[0, 0]) * 1000) for f in frames] == [1003, 1004, 1005, 1006], fmt
            assert stats.depth_messages == 4
            # the frames keep their own (header) stamps: pairing and poses use those
            assert frames[0].stamp_ns == T0 - DEVICE_LAG_NS + 300_000_000
