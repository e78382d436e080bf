"""Depth images at another size than their camera info with the same aspect ratio (a decimation filter that left
the camera info as it was, image_proc's resize): the intrinsics are scaled, and that is said."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner
from recordings import K, make_recording

from kinfu_cli.cli import cli
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording


def test_half_size_depth_gets_half_the_intrinsics(tmp_path):
    path = make_recording(tmp_path / "decimated.mcap", n=3, info_size=(40, 32))  # info for 40x32, depth 20x16
    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, stats=stats))
    want = K.copy()  # K of the recording is given for the 20x16 images; its info claims twice the size
    want[0, 0], want[1, 1] = K[0, 0] * 0.5, K[1, 1] * 0.5
    want[0, 2], want[1, 2] = (K[0, 2] + 0.5) * 0.5 - 0.5, (K[1, 2] + 0.5) * 0.5 - 0.5
    assert len(frames) == 3
    np.testing.assert_allclose(frames[0].K, want)
    assert len(stats.notes) == 1 and "scaled by 0.5" in stats.notes[0] and "20x16" in stats.notes[0]
    out = tmp_path / "fused"
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(out), "--voxel-size", "0.02", "--quiet",
                                   "--pose", "forced"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    assert any("scaled by 0.5" in w for w in report["warnings"])
