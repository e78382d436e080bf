"""A colour image whose size is not its camera info's (another aspect ratio: not a resize of that camera) costs
the colour, not the run: the depth is fused without colour and one warning names the colour topic and both sizes.

Before: `kinfu fuse` of such a recording stopped at the first frame with `kinfu: error: ...: colour image is
40x20 but camera info /camera/color/camera_info says 32x24` (exit 2), though the depth was good.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter

S = 1_000_000_000
W, H = 32, 24
K = np.array([[30.0, 0, 15.5], [0, 30.0, 11.5], [0, 0, 1]])
T_DEPTH_COLOR = np.eye(4)
T_DEPTH_COLOR[:3, 3] = [0.015, 0.0, 0.0]
T_WORLD_DEPTH = np.array([[1.0, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 1.0], [0, 0, 0, 1]])  # looking down at z = 0


def _recording(path, color_shape, switch_at=None):
    """Depth of a floor 1 m below, colour from a camera 1.5 cm aside whose info says W x H; the colour images
    are color_shape (H, W) (from frame switch_at on, when given; W x H before)."""
    with RecordingWriter(path) as w:
        w.write_tf(S, [("camera_depth_optical_frame", "camera_color_optical_frame", T_DEPTH_COLOR)], static=True)
        for i in range(4):
            t = S + i * S // 10
            w.write_tf(t, [("world", "camera_depth_optical_frame", T_WORLD_DEPTH)])
            w.write_image("/camera/depth/image_raw", t, "camera_depth_optical_frame",
                          np.full((H, W), 1000, np.uint16), "16UC1")
            w.write_camera_info("/camera/depth/camera_info", t, "camera_depth_optical_frame", K, W, H)
            shape = color_shape if switch_at is None or i >= switch_at else (H, W)
            w.write_image("/camera/color/image_raw", t, "camera_color_optical_frame",
                          np.full((*shape, 3), 200, np.uint8), "rgb8")
            w.write_camera_info("/camera/color/camera_info", t, "camera_color_optical_frame", K, W, H)
    return path


@pytest.mark.parametrize("switch_at", [None, 2])
def test_colour_of_another_aspect_costs_the_colour_only(tmp_path, switch_at):
    path = _recording(tmp_path / "r.mcap", (20, 40), switch_at)
    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, stats=stats))
    assert len(frames) == 4 and all(np.allclose(f.depth, 1.0) for f in frames)
    coloured = 0 if switch_at is None else switch_at
    assert sum(f.color is not None for f in frames) == coloured and stats.without_color == 4 - coloured
    (w,) = stats.warnings("r.mcap")
    assert "/camera/color/image_raw" in w and "40x20" in w and "32x24" in w, w


def test_fuse_goes_on_without_colour_and_says_why(tmp_path):
    path = _recording(tmp_path / "r.mcap", (20, 40))
    out = tmp_path / "fused"
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(out), "--voxel-size", "0.02", "--size", "1,1,0.4",
                                   "--origin", "-0.5,-0.5,-0.2", "--quiet"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    assert report["frames"]["used"] == 4 and report["frames"]["without_color"] == 4
    assert report["counts"]["occupied"] > 0
    hits = [w for w in report["warnings"] if "40x20" in w]
    assert len(hits) == 1 and "/camera/color/image_raw" in hits[0] and "32x24" in hits[0], report["warnings"]


def test_a_resized_colour_image_keeps_its_colour(tmp_path):
    """Half the camera info's size, the same aspect ratio: image_proc's resize, still coloured."""
    path = _recording(tmp_path / "r.mcap", (12, 16))
    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, stats=stats))
    assert all(f.color is not None for f in frames) and stats.warnings("r.mcap") == []
