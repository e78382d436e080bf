"""A --start / --end window outside the recording (a start after its end, an end before its start) selects no
frame: that is said naming the option and the recording's length, not as "no usable depth frames"."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter

T0 = 1_700_000_000 * 10 ** 9


def _recording(path):
    K = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]])
    with RecordingWriter(path) as w:
        for k in range(5):  # 10 Hz: 0.4 s long
            stamp = T0 + k * 100_000_000
            w.write_camera_info("/camera/depth/camera_info", stamp, "camera_depth_optical_frame", K, 64, 48)
            w.write_image("/camera/depth/image_raw", stamp, "camera_depth_optical_frame",
                          np.full((48, 64), 1000, np.uint16), "16UC1")
    return path


@pytest.mark.parametrize("window, parameter", [(dict(start_s=1e6), "start_s"), (dict(start_s=0.5), "start_s"),
                                               (dict(end_s=-1.0), "end_s"), (dict(start_s=-5, end_s=-2), "end_s")])
def test_a_window_outside_the_recording_is_named(tmp_path, window, parameter):
    with open_recording(_recording(tmp_path / "r.mcap")) as rec:
        with pytest.raises(ConfigError) as info:
            list(iter_frames(rec, pose_source="none", **window))
        assert info.value.parameter == parameter
        assert ("lasts 0.400 s" if parameter == "start_s" else "before the recording's start") in str(info.value)
        # inside (or overlapping) windows still select their frames
        assert len(list(iter_frames(rec, pose_source="none", start_s=-1.0, end_s=0.15))) == 2
        assert len(list(iter_frames(rec, pose_source="none", start_s=0.4))) == 1


def test_commands_name_the_option(tmp_path):
    rec = _recording(tmp_path / "r.mcap")
    line = one_line_error(CliRunner().invoke(cli, ["export", str(rec), "-o", str(tmp_path / "e"), "-q",
                                                   "--pose-source", "none", "--start", "1e6"]), "--start")
    assert "0.400 s" in line and not (tmp_path / "e").exists()
    one_line_error(CliRunner().invoke(cli, ["info", str(rec), "--frames", "-q", "--pose-source", "none",
                                            "--end", "-1"]), "--end", "before the recording's start")
