"""Frames fuse counted as used but did not feed the grid: a TF that jumps 5 m for some frames put all their readings
outside it (counted as used, no word), and empty depth images dropped half the frames with only a count."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.fusion.outputs import fusion_report
from kinfu_cli.fusion.pipeline import fuse_recording
from kinfu_cli.io.writers import RecordingWriter

S = 1_000_000_000
T0 = 1_600_000_000 * S
W, H = 24, 18
K = np.array([[20.0, 0, 11.5], [0, 20.0, 8.5], [0, 0, 1]])
GRID = dict(size=1.0, voxel_size=0.05, origin=(-0.5, -0.5, 0.5))  # holds the wall 1 m in front of the camera


def _recording(path, jump=(), empty=(), far=(), n=6):
    """A camera 1 m from a wall, TF world -> camera_optical per frame; frames in `jump` 5 m off, those in `empty`
    without a valid pixel, those in `far` seeing it 5 m away (beyond the default max_depth)."""
    with RecordingWriter(path) as w:
        for i in range(n):
            stamp = T0 + i * S // 10
            T = np.eye(4)
            T[0, 3] = 5.0 if i in jump else 0.01 * i
            w.write_tf(stamp, [("world", "camera_optical", T)])
            depth = np.full((H, W), 0 if i in empty else 5000 if i in far else 1000, np.uint16)
            w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth, "16UC1")
            w.write_camera_info("/camera/depth/camera_info", stamp, "camera_optical", K, W, H)
    return path


def test_frames_whose_readings_all_miss_the_grid_are_named(tmp_path):
    res = fuse_recording(_recording(tmp_path / "jump.mcap", jump=(3, 4, 5)), color=False, **GRID)
    assert res.frames_used == 6
    assert res.frames_outside_grid == [3, 4, 5]
    said = [w for w in res.warnings if "inside the grid" in w]
    assert len(said) == 1 and "3 of the 6 frames fused" in said[0] and "frames 3, 4, 5" in said[0]
    assert fusion_report(res)["frames"]["outside_grid"] == [3, 4, 5]


def test_frames_in_the_grid_are_not_named(tmp_path):
    res = fuse_recording(_recording(tmp_path / "still.mcap"), color=False, **GRID)
    assert res.frames_outside_grid == []
    assert not [w for w in res.warnings if "inside the grid" in w]


def test_many_empty_depth_frames_are_a_warning(tmp_path):
    """Half the frames without a valid pixel: a warning as for missing poses (over 10 %), not only a count."""
    path = _recording(tmp_path / "empty.mcap", empty=(3, 4, 5))
    out = tmp_path / "fused"
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(out), "--voxel-size", "0.05", "--size", "1.0",
                                   "--origin", "-0.5,-0.5,0.5", "--quiet", "--no-color"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    assert report["frames"]["dropped"] == {"depth image has no valid pixel": 3}
    said = [w for w in report["warnings"] if "no valid depth reading" in w]
    assert len(said) == 1 and "3 of the 6 depth frames selected" in said[0]
    assert f"kinfu: warning: {said[0]}" in res.output


def test_a_few_empty_depth_frames_are_only_counted(tmp_path):
    res = fuse_recording(_recording(tmp_path / "one.mcap", empty=(5,), n=12), color=False, **GRID)
    assert res.dropped == {"depth image has no valid pixel": 1}
    assert not [w for w in res.warnings if "no valid depth reading" in w]


def test_depth_left_empty_by_the_range_counts_too(tmp_path):
    """Frames whose readings all lie beyond max_depth are dropped by the depth filter, and count with the empty
    ones; the share is of the frames selected (every 2nd: 2 of 3), not of all depth messages (2 of 6)."""
    path = _recording(tmp_path / "far.mcap", empty=(2,), far=(4,))
    res = fuse_recording(path, color=False, every=2, **GRID)
    said = [w for w in res.warnings if "no valid depth reading" in w]
    assert len(said) == 1 and "2 of the 3 depth frames selected" in said[0]
    assert "depth image has no valid pixel: 1" in said[0] and "after filtering: 1" in said[0]
