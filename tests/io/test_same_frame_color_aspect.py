"""Colour in the depth camera's own frame is used as the depth's pixels resized: of another aspect ratio it is
another camera, and stretching it would paint colours beside their surfaces. It then costs the colour (one
warning naming the topic and both sizes), not the run; a plain resize keeps the colour.

Before: a 40x20 colour image beside 32x24 depth in the same frame was stretched to 32x24 without a word."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter

S = 1_000_000_000
W, H = 32, 24
K = np.array([[30.0, 0, 15.5], [0, 30.0, 11.5], [0, 0, 1]])
T_WORLD_DEPTH = np.array([[1.0, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 1.0], [0, 0, 0, 1]])


def _recording(path, color_shape):
    with RecordingWriter(path) as w:
        for i in range(3):
            t = S + i * S // 10
            w.write_tf(t, [("world", "camera_optical", T_WORLD_DEPTH)])
            w.write_image("/camera/depth/image_raw", t, "camera_optical", np.full((H, W), 1000, np.uint16), "16UC1")
            w.write_camera_info("/camera/depth/camera_info", t, "camera_optical", K, W, H)
            w.write_image("/camera/color/image_raw", t, "camera_optical", np.full((*color_shape, 3), 200, np.uint8),
                          "rgb8")
    return path


@pytest.mark.parametrize("shape, coloured", [((20, 40), False), ((48, 64), True), ((24, 32), True)])
def test_same_frame_colour_of_another_aspect_is_left_out(tmp_path, shape, coloured):
    path = _recording(tmp_path / "r.mcap", shape)
    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, stats=stats))
    assert len(frames) == 3 and all(np.allclose(f.depth, 1.0) for f in frames)
    assert all((f.color is not None) == coloured for f in frames)
    warnings = stats.warnings("r.mcap")
    if coloured:
        assert warnings == []
    else:
        (w,) = warnings
        assert "/camera/color/image_raw" in w and "40x20" in w and "32x24" in w, w
