"""The colour look-ahead at the end of a time window and at its own bound.

Colour logged late (after its stamp) near the end of a --end window used to be past the read end: the last frames
took a neighbouring colour image without a word, or none with a false "no colour image at all". And a depth frame
logged exactly COLOR_LOOKAHEAD_NS late, that got its own colour image, was counted as cut short because a farther
neighbour had been dropped."""

from __future__ import annotations


from kinfu_cli.io.rgbd_frame import COLOR_LOOKAHEAD_NS
from recordings import LATE_PERIOD, LATE_T0, read_frames, write_logged

T0, PERIOD = LATE_T0, LATE_PERIOD


def _recording(path, events):
    """events: (log ns, "colour" | "depth", k) (tests/recordings.write_logged)."""
    return write_logged(path, events)


def _depth_k(frame) -> int:
    return int(round(float(frame.depth[0, 0]) * 1000)) - 1000


def test_colour_logged_late_after_the_window_end_is_read_for_its_last_frames(tmp_path):
    late = 300_000_000
    n = 60
    events = [(T0 + k * PERIOD, "depth", k) for k in range(n)]
    events += [(T0 + k * PERIOD + late, "colour", k) for k in range(n)]
    path = _recording(tmp_path / "colour_late.mcap", events)
    frames, stats = read_frames(path, start_s=0.5, end_s=1.0)
    end_ns = T0 + 1_000_000_000
    in_window = [k for k in range(n) if T0 + 500_000_000 <= T0 + k * PERIOD <= end_ns]
    assert [_depth_k(f) for f in frames] == in_window  # depth after the window is neither used nor counted
    assert stats.depth_messages == len(in_window)
    assert [int(f.color[0, 0, 0]) if f.color is not None else None for f in frames] == in_window
    assert stats.without_color == 0 and stats.color_cut_short == 0
    assert not stats.warnings("rec")


def _depth_late(tmp_path, latency_ns):
    n = 120
    events = [(T0 + k * PERIOD, "colour", k) for k in range(n)]
    events += [(T0 + k * PERIOD + latency_ns, "depth", k) for k in range(0, n, 3)]
    return read_frames(_recording(tmp_path / "depth_late.mcap", events))


def test_depth_logged_one_lookahead_late_with_its_own_colour_is_not_cut_short(tmp_path):
    frames, stats = _depth_late(tmp_path, COLOR_LOOKAHEAD_NS)
    assert [int(f.color[0, 0, 0]) for f in frames] == [_depth_k(f) for f in frames]
    assert stats.color_cut_short == 0
    assert not any("no longer kept" in w for w in stats.warnings("rec"))


def test_depth_that_lost_its_nearest_colour_is_still_cut_short(tmp_path):
    frames, stats = _depth_late(tmp_path, COLOR_LOOKAHEAD_NS + 40_000_000)
    carried_other = sum(f.color is not None and int(f.color[0, 0, 0]) != _depth_k(f) for f in frames)
    assert carried_other > 0
    assert stats.color_cut_short >= carried_other
    assert any("no longer kept" in w for w in stats.warnings("rec"))
