"""Depth images logged later than the colour images of the same instant are paired by stamp all the same.

A depth driver's processing and the recorder's queue log depth images some 30-300 ms after their header stamp,
while colour is logged at once. The pairer used to forget colour images by the latest colour stamp whenever no
depth frame was waiting, so the colour of a depth frame still to come was gone: frames took a neighbouring image
(no word said) or none (with a false "nearest colour image 100 ms away")."""

from __future__ import annotations

import pytest

from kinfu_cli.io.frame_pairing import FramePairer
from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.rgbd_frame import COLOR_LOOKAHEAD_NS
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter
from recordings import LATE_H, LATE_K, LATE_PERIOD, LATE_T0, LATE_W, read_frames, write_logged

T0, PERIOD = LATE_T0, LATE_PERIOD  # colour at 30 Hz
W, H, K = LATE_W, LATE_H, LATE_K


def _recording(path, latency_ns: int, n_colour: int = 30, depth_every: int = 3, depth_until: int | None = None,
               depth_ks=None):
    """Colour k stamped and logged at T0 + k * PERIOD; a depth image at every `depth_every`-th colour stamp (up to
    colour `depth_until`; or at colours `depth_ks`), logged `latency_ns` later, with its camera info."""
    depth_until = n_colour if depth_until is None else depth_until
    depth_ks = range(0, depth_until, depth_every) if depth_ks is None else depth_ks
    events = [(T0 + k * PERIOD, "colour", k) for k in range(n_colour)]
    events += [(T0 + k * PERIOD + latency_ns, "depth", k) for k in depth_ks]
    return write_logged(path, events)


def _colour_index(frame) -> int:
    """Which colour image a frame carries (its depth says which one it should)."""
    return int(frame.color[0, 0, 0])


@pytest.mark.parametrize("latency_ms", [0, 80, 150, 400])
def test_depth_logged_late_is_paired_with_the_colour_of_its_stamp(tmp_path, latency_ms):
    frames, stats = read_frames(_recording(tmp_path / "r.mcap", latency_ms * 1_000_000))
    assert len(frames) == 10 and stats.without_color == 0
    for f in frames:
        assert f.color is not None and _colour_index(f) == round(float(f.depth[0, 0]) * 1000) - 1000
    assert stats.color_cut_short == 0 and stats.warnings("r.mcap") == []


def test_depth_logged_late_in_a_time_window_finds_colour_logged_before_it(tmp_path):
    # depth logged 150 ms late: the first frame of a window starting at 0.5 s has its colour logged at ~0.35 s,
    # before the window and its tolerance margin
    frames, stats = read_frames(_recording(tmp_path / "w.mcap", 150_000_000), start_s=0.5, end_s=0.8)
    assert [round(float(f.depth[0, 0]) * 1000) - 1000 for f in frames] == [12, 15, 18]
    assert [_colour_index(f) for f in frames] == [12, 15, 18] and stats.without_color == 0
    assert frames[0].index == 0  # counted from the window's start minus the tolerance, as before


def test_depth_logged_later_than_the_look_ahead_is_said(tmp_path):
    # depth logged 1.5 s after its stamp while colour goes on: the colour of its stamp was no longer kept
    latency = COLOR_LOOKAHEAD_NS + 500_000_000
    frames, stats = read_frames(_recording(tmp_path / "l.mcap", latency, n_colour=90, depth_until=30))
    assert len(frames) == 10 and stats.color_cut_short == 10
    assert all(f.color is None or _colour_index(f) != round(float(f.depth[0, 0]) * 1000) - 1000 for f in frames)
    said = [w for w in stats.warnings("l.mcap") if "no longer kept" in w]
    assert len(said) == 1 and said[0].startswith("l.mcap: 10 depth frames were logged more than 1 s after")
    assert stats.as_dict()["color_cut_short"] == 10


def test_a_pause_of_the_depth_stream_is_no_cut_short_pairing(tmp_path):
    # depth (logged 100 ms late) pauses 2 s while colour goes on: colour of the pause is dropped, none is missed
    ks = [0, 3, 6, 9, 75, 78, 81]
    frames, stats = read_frames(_recording(tmp_path / "p.mcap", 100_000_000, n_colour=90, depth_ks=ks))
    assert [_colour_index(f) for f in frames] == ks and stats.without_color == 0
    assert stats.color_cut_short == 0 and stats.warnings("p.mcap") == []


def test_colour_kept_for_depth_to_come_is_bounded(tmp_path, monkeypatch):
    # a depth stream that stops while colour goes on: colour is not hoarded beyond the look-ahead
    path = _recording(tmp_path / "s.mcap", 0, n_colour=150, depth_until=3)
    held = []
    forget = FramePairer._forget_colors

    def counted(self, log_ns):
        forget(self, log_ns)
        held.append(len(self.colors))

    monkeypatch.setattr(FramePairer, "_forget_colors", counted)
    frames, _ = read_frames(path)
    assert len(frames) == 1 and _colour_index(frames[0]) == 0
    assert len(held) == 150 and max(held) <= COLOR_LOOKAHEAD_NS // PERIOD + 2


def test_a_frame_waiting_for_its_colour_keeps_the_camera_info_of_its_time(tmp_path):
    """A depth frame waits for the colour image after it before it is emitted; the camera info logged in between
    (the next frame's, the camera re-calibrated) was taken for it: frame 2 got frame 3's focal length."""
    from recordings import H, K, W, color, depth_mm

    path = tmp_path / "recal.mcap"
    t0 = 1_600_000_000 * 10**9
    with RecordingWriter(path) as w:
        for i in range(6):
            t = t0 + i * 100_000_000  # 10 Hz: a frame's colour partner beyond the tolerance comes after the next info
            Ki = K.copy()
            Ki[0, 0] = Ki[1, 1] = 30.0 if i < 3 else 36.0
            w.write_camera_info("/camera/depth/camera_info", t, "cam", Ki, W, H)
            w.write_image("/camera/depth/image_raw", t, "cam", depth_mm(i), "16UC1")
            w.write_image("/camera/color/image_raw", t, "cam", color(i), "rgb8")
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, pose_source="none"))
    assert [f.K[0, 0] for f in frames] == [30.0, 30.0, 30.0, 36.0, 36.0, 36.0]
    assert all(f.color is not None and f.color[0, 0, 0] == f.index for f in frames)
