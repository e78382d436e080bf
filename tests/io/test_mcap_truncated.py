"""An MCAP file cut short (recorder killed): read up to its last whole chunk, with the loss said, not refused."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.recording import open_recording


def _cut(src, dst, share):
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * share)])
    return dst


def test_cut_short_recording_gives_the_frames_before_the_cut(sample_dir, tmp_path):
    whole = sample_dir / "recording.mcap"
    cut = _cut(whole, tmp_path / "cut.mcap", 0.7)
    with open_recording(whole) as rec:
        full = list(iter_frames(rec))
    with open_recording(cut) as rec:
        assert rec.problems and "truncated" in rec.problems[0] and "cut.mcap" in rec.problems[0]
        depth_topic = "/camera/depth/image_raw/compressedDepth"
        n = rec.topics[depth_topic].count
        stamps = [t for _, t, _ in rec.messages([depth_topic])]
        part = list(iter_frames(rec))
    assert 0 < n < rec_count(whole, depth_topic) and stamps == sorted(stamps) and len(stamps) == n
    assert len(part) >= n - 1  # the last depth image may lack its colour partner's window: kept without colour
    for a, b in zip(part, full):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_allclose(a.T_world_camera, b.T_world_camera, atol=1e-9)


def rec_count(path, topic):
    with open_recording(path) as rec:
        return rec.topics[topic].count


def test_cut_before_any_channel_is_an_error(sample_dir, tmp_path):
    cut = _cut(sample_dir / "recording.mcap", tmp_path / "stub.mcap", 0.0001)
    with pytest.raises(RecordingError, match="stub.mcap"):
        with open_recording(cut) as rec:
            list(iter_frames(rec))


def test_ros2_folder_of_a_killed_recording(sample_dir, tmp_path):
    """`ros2 bag record` writes metadata.yaml when it stops: a killed one leaves only its storage file."""
    folder = tmp_path / "killed"
    folder.mkdir()
    _cut(sample_dir / "recording.mcap", folder / "killed_0.mcap", 0.7)
    with open_recording(folder) as rec:
        assert len(rec.problems) == 2 and "without metadata.yaml" in rec.problems[0]
        assert len(list(iter_frames(rec))) > 0
    sqlite = tmp_path / "sqlite"
    sqlite.mkdir()
    (sqlite / "killed_0.db3").write_bytes(b"SQLite format 3\x00" + bytes(100))
    with pytest.raises(RecordingError, match="ros2 bag reindex"):
        open_recording(sqlite)


def test_poi_from_a_cut_short_recording_says_so(sample_dir, tmp_path):
    from click.testing import CliRunner

    from kinfu_cli.cli import cli

    cut = _cut(sample_dir / "recording.mcap", tmp_path / "cut.mcap", 0.97)
    res = CliRunner().invoke(cli, ["poi", str(cut), "-o", str(tmp_path / "pois.json"), "--json"])
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: " in res.output and "truncated" in res.output


def test_export_of_a_cut_short_recording_says_so(sample_dir, tmp_path):
    """export (frames and trajectory) says what was lost, in frames.json and on stderr, as fuse and poi do."""
    import json

    from click.testing import CliRunner

    from kinfu_cli.cli import cli

    cut = _cut(sample_dir / "recording.mcap", tmp_path / "cut.mcap", 0.97)
    res = CliRunner().invoke(cli, ["export", str(cut), "-o", str(tmp_path / "frames"), "--every", "10", "--quiet"])
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: " in res.output and "truncated" in res.output
    doc = json.loads((tmp_path / "frames" / "frames.json").read_text())
    assert len(doc["warnings"]) == 1 and "truncated" in doc["warnings"][0]
    res = CliRunner().invoke(cli, ["export", str(cut), "--trajectory", "tum", "-o", str(tmp_path / "gt.tum"),
                                   "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: " in res.output and "truncated" in res.output
