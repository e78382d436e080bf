"""Intrinsics given for an organized cloud are used, but when they do not put the cloud's points on their pixels
(another camera's, a typo) that is said: the depth was silently unprojected with a wrong lens."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.pointcloud2 import organized_cloud
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles
from kinfu_cli.io.writers import RecordingWriter

K = np.array([[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1]])


@pytest.mark.parametrize("given, warned", [("40,40,15.5,11.5", False), ("80,80,15.5,11.5", True)])
def test_given_intrinsics_that_miss_the_points_are_said(tmp_path, given, warned):
    depth = np.full((24, 32), 0.9) + np.linspace(0, 0.2, 32)[None, :]
    path = tmp_path / "c.mcap"
    with RecordingWriter(path) as w:
        w.write_pointcloud2("/camera/depth/points", 1_000_000_000, "cam", organized_cloud(depth, K))
    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, detect_roles(rec, intrinsics=given), pose_source="none", stats=stats))
    assert len(frames) == 1 and np.allclose(frames[0].depth, depth, atol=1e-6)
    notes = [n for n in stats.notes if "given intrinsics miss its points" in n]
    assert bool(notes) == warned, stats.notes
    if warned:
        assert "/camera/depth/points" in notes[0] and "px RMS" in notes[0]
