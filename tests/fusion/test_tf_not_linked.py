"""A recording whose TF tree does not reach the camera (a missing static link): fuse tracks with ICP, and says
that it did, instead of falling back silently."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter


def test_unlinked_camera_is_a_warning(sample_dir, tmp_path):
    path = tmp_path / "unlinked.mcap"
    with open_recording(sample_dir / "recording.mcap") as rec, RecordingWriter(path) as w:
        frames = list(iter_frames(rec, end_s=3.0))
        w.write_tf(frames[0].stamp_ns, [("world", "base_link", np.eye(4))], static=True)  # no link to the camera
        for f in frames:
            w.write_image("/camera/depth/image_raw", f.stamp_ns, "camera_optical",
                          np.round(f.depth * 1000).astype(np.uint16), "16UC1")
            h, wd = f.depth.shape
            w.write_camera_info("/camera/depth/camera_info", f.stamp_ns, "camera_optical", f.K, wd, h)
    out = tmp_path / "fused"
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(out), "--voxel-size", "0.02", "--size", "2.0",
                                   "--quiet", "--no-color"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    assert report["pose_mode"] == "icp"
    said = [w for w in report["warnings"] if "does not link camera frame camera_optical" in w]
    assert said and "ICP" in said[0]
    assert "kinfu: warning: " in res.output
