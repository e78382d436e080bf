"""`fuse --max-lost` with --start/--end: the early stop counts the frames the time window can select, not every
depth message of the recording."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.fusion import pipeline
from kinfu_cli.fusion.tracking import TrackResult
from kinfu_cli.io.frames import FrameStats, iter_frames, window_depth_count
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles


@pytest.mark.parametrize("name", ["recording.mcap", "recording.bag", "recording_ros2"])
def test_window_count_bounds_the_frames_selected(sample_dir, name):
    """In every container: the count covers every frame the window selects, and no more than the messages read
    for it (the window widened by the tolerance); without a window it is the topic's count."""
    with open_recording(sample_dir / name) as rec:
        roles = detect_roles(rec)
        total = rec.topics[roles.depth_topic].count
        assert window_depth_count(rec, roles.depth_topic) == total
        stamps = np.array([t for _, t, _ in rec.messages(roles.depth_topic)]) - rec.start_ns
        for start, end in ((1.0, 3.0), (5.0, None)):
            stats = FrameStats()
            selected = sum(1 for _ in iter_frames(rec, roles, start_s=start, end_s=end, stats=stats))
            n = window_depth_count(rec, roles.depth_topic, start, end)
            lo = -np.inf if start is None else start * 1e9 - 0.05e9
            hi = np.inf if end is None else end * 1e9 + 0.05e9
            assert n == int(((stamps >= lo) & (stamps <= hi)).sum()), (start, end)
            assert selected <= stats.depth_messages <= n < total or start is None and end is None


def _always_lost(self, vol, depth, K, candidates, **kw):
    return TrackResult(T_world_camera=candidates[0], fitness=0.0, rmse=float("nan"), lost=True, reason="test")


def test_max_lost_stops_on_the_share_of_the_window(sample_dir, tmp_path, monkeypatch):
    """Every tracked frame lost: with --end 4 (n depth messages in the window) and --max-lost 50 %, the run
    stops as soon as more than n/2 are lost, naming n; before the fix the bound was all 36 messages, so the
    run read the whole window and failed only at the end."""
    monkeypatch.setattr(pipeline.FrameToModelTracker, "track", _always_lost)
    rec = sample_dir / "recording.mcap"
    with open_recording(rec) as r:
        n = window_depth_count(r, detect_roles(r).depth_topic, None, 4.0)
        assert 4 <= n < r.topics[detect_roles(r).depth_topic].count
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(out), "--pose", "icp", "--end", "4", "--max-lost",
                                   "50%", "--resolution", "32", "--size", "1.5", "--quiet"])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: --max-lost:"), res.output
    lost = n // 2 + 1
    assert f"lost {lost} of {lost} tracked frames" in lines[0], lines[0]
    assert f"stopped: more than 50 % of the {n} frames selected" in lines[0], lines[0]
    assert not out.exists()
