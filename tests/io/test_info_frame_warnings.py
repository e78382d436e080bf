"""`kinfu info --frames` says what fuse and export say about the frames: before, a recording whose depth was logged
1.1 s late printed only "without colour 40" (and color_cut_short: 40 in the JSON), none of the warnings."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli
from recordings import LATE_PERIOD, LATE_T0, write_logged

T0, PERIOD = LATE_T0, LATE_PERIOD


def _depth_logged_late(path, latency_ns=1_100_000_000, n=90):
    """Colour at 30 Hz logged at its stamp; depth at every third colour stamp, logged latency_ns late."""
    events = [(T0 + k * PERIOD, "colour", k) for k in range(n)]
    events += [(T0 + k * PERIOD + latency_ns, "depth", k) for k in range(0, n, 3)]
    return write_logged(path, events)


def _warnings(res) -> list[str]:
    return [line for line in res.stderr.splitlines() if line.startswith("kinfu: warning: ")]


def test_info_frames_prints_the_frame_warnings(tmp_path):
    path = _depth_logged_late(tmp_path / "late.mcap")
    res = CliRunner().invoke(cli, ["info", str(path), "--frames", "-q", "--pose-source", "none"])
    assert res.exit_code == 0, res.output
    said = _warnings(res)
    assert any("frames have no colour" in w for w in said), res.stderr
    assert any("no longer kept" in w for w in said), res.stderr
    assert len(res.stderr.splitlines()) == len(said)  # nothing else on stderr

    res = CliRunner().invoke(cli, ["info", str(path), "--frames", "-q", "--pose-source", "none", "--json"])
    doc = json.loads(res.stdout)
    assert doc["frames"]["color_cut_short"] > 0 and len(doc["warnings"]) == len(said) == len(_warnings(res))


def test_info_without_frames_prints_no_frame_warnings(tmp_path):
    res = CliRunner().invoke(cli, ["info", str(_depth_logged_late(tmp_path / "late.mcap"))])
    assert res.exit_code == 0, res.output
    assert not _warnings(res)
