"""Depth, colour and camera info are paired by their header stamps, not by the order the recorder logged them in.

Before: a camera info logged just after its image (image_transport publishes the image, then the info) was taken
for the next depth frame, so the frame at a re-calibration or a resolution change was read with the old camera
(or refused); a depth image logged after a later-stamped one had lost its colour, and the warning blamed the
tolerance; colour stamps running backwards (a driver restart) went unsaid, and a depth frame could take a colour
image of the other pass; a rectified colour topic in the depth camera's frame was undistorted a second time with
the depth camera's D; a projected colour camera's later camera infos were not read (its first one served all)."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.io.writers import RecordingWriter
from recordings import read_frames

S = 1_000_000_000
T0 = 1_700_000_000 * S
PERIOD = 33_333_333  # 30 Hz
DEPTH, INFO, COLOUR = "/camera/depth/image_raw", "/camera/depth/camera_info", "/camera/color/image_raw"


def _K(f: float, w: int, h: int) -> np.ndarray:
    return np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])


def _depth_k(frame) -> int:
    """Which depth image a frame is: image k reads 1000 + k mm."""
    return int(round(float(frame.depth[0, 0]) * 1000)) - 1000


def _colour_k(frame) -> int | None:
    return None if frame.color is None else int(frame.color[0, 0, 0])


def _write(path, events):
    """events: (log ns, kind, k, extra) with kind "depth" (extra: (w, h)), "info" (extra: (f, w, h)) or "colour"
    (extra: its red value);
    image k is stamped T0 + k * PERIOD; written in log order, ties in the order given."""
    with RecordingWriter(path) as w:
        for log_ns, kind, k, extra in sorted(events, key=lambda e: e[0]):
            stamp = T0 + k * PERIOD
            if kind == "depth":
                dw, dh = extra
                w.write_image(DEPTH, stamp, "cam", np.full((dh, dw), 1000 + k, np.uint16), "16UC1", log_ns=log_ns)
            elif kind == "info":
                f, iw, ih = extra
                w.write_camera_info(INFO, stamp, "cam", _K(f, iw, ih), iw, ih, log_ns=log_ns)
            else:  # extra: its red value (k when None)
                red = k if extra is None else extra
                w.write_image(COLOUR, stamp, "cam", np.full((6, 8, 3), [red, 200, 7], np.uint8), "rgb8",
                              log_ns=log_ns)
    return path


def _recalibrated(n=6, change=3, colour=False, info_first=False, new=(12.0, 8, 6)):
    """Depth k with its camera info (logged after it, as image_transport does, or before), the camera changing at
    frame `change` from 10 px focal length on 8x6 to `new`; optionally colour at every stamp."""
    events = []
    for k in range(n):
        t = T0 + k * PERIOD
        f, w, h = (10.0, 8, 6) if k < change else new
        image, info = (t, "depth", k, (w, h)), (t, "info", k, (f, w, h))
        events += [info, image] if info_first else [image, info]
        if colour:
            events.append((t - 1, "colour", k, None))
    return events


# ------------------------------------------------------------------------------------- 1. camera info by stamp
@pytest.mark.parametrize("colour", [False, True])
def test_a_camera_info_logged_after_its_image_is_that_images(tmp_path, colour):
    frames, stats = read_frames(_write(tmp_path / "r.mcap", _recalibrated(colour=colour)))
    assert [_depth_k(f) for f in frames] == list(range(6))
    assert [f.K[0, 0] for f in frames] == [10.0, 10.0, 10.0, 12.0, 12.0, 12.0]
    assert stats.warnings("r.mcap") == []


def test_a_camera_info_logged_before_its_image_is_still_that_images(tmp_path):
    frames, _ = read_frames(_write(tmp_path / "r.mcap", _recalibrated(info_first=True)))
    assert [f.K[0, 0] for f in frames] == [10.0, 10.0, 10.0, 12.0, 12.0, 12.0]


def test_a_resolution_change_is_read_with_the_new_camera_info(tmp_path):
    # 8x6 -> 10x6 at frame 3: read with the info of the 8x6 images, frame 3 was refused (another aspect ratio)
    frames, stats = read_frames(_write(tmp_path / "r.mcap", _recalibrated(new=(11.0, 10, 6))))
    assert [f.depth.shape for f in frames] == [(6, 8)] * 3 + [(6, 10)] * 3
    assert [f.K[0, 0] for f in frames] == [10.0] * 3 + [11.0] * 3
    assert [f.K[0, 2] for f in frames] == [3.5] * 3 + [4.5] * 3
    assert stats.notes == []


def test_without_an_info_of_its_stamp_a_frame_takes_the_latest_before_it(tmp_path):
    # the camera info is published once a second with stamps of its own: each frame takes the one logged before it
    events = [(T0 + k * PERIOD, "depth", k, (8, 6)) for k in range(40)]
    events += [(T0 + 5_000_000, "info", 0, (10.0, 8, 6)), (T0 + S + 5_000_000, "info", 31, (12.0, 8, 6))]
    frames, _ = read_frames(_write(tmp_path / "r.mcap", events))
    logged_after_second_info = [T0 + k * PERIOD > T0 + S + 5_000_000 for k in range(40)]
    assert [f.K[0, 0] for f in frames] == [12.0 if a else 10.0 for a in logged_after_second_info]


def test_a_camera_info_of_the_last_frame_after_the_window_end_is_read(tmp_path):
    events = _recalibrated(n=12, change=6)
    events = [(log + (1 if kind == "info" else 0), kind, k, x) for log, kind, k, x in events]  # info 1 ns later
    end_s = (6 * PERIOD) / S  # the window ends at depth 6, the first of the new camera
    frames, _ = read_frames(_write(tmp_path / "r.mcap", events), end_s=end_s)
    assert [_depth_k(f) for f in frames][-1] == 6 and frames[-1].K[0, 0] == 12.0


# ------------------------------------------------------------------------------- 2. depth out of stamp order
def test_depth_logged_out_of_stamp_order_keeps_its_colour(tmp_path):
    events = [(T0 + k * PERIOD, "colour", k, None) for k in range(30)]
    late = {k: 50_000_000 for k in range(0, 30, 3)}
    late[6] = 200_000_000  # depth 6 is logged after depth 9
    for k, latency in late.items():
        events += [(T0 + k * PERIOD + latency, "depth", k, (8, 6)), (T0 + k * PERIOD + latency, "info", k,
                                                                    (10.0, 8, 6))]
    frames, stats = read_frames(_write(tmp_path / "r.mcap", events))
    assert [_depth_k(f) for f in frames] == [0, 3, 9, 6, 12, 15, 18, 21, 24, 27]
    assert [_colour_k(f) for f in frames] == [_depth_k(f) for f in frames]
    assert stats.color_unpaired == 0 and stats.stamps_not_increasing == 1
    (warning,) = stats.warnings("r.mcap")
    assert "earlier than the one before" in warning and "tolerance" not in warning


# ---------------------------------------------------------------------------------- 3. colour running backwards
def _restart(path, back, depth_restarts, late_depth=False, depth_first=False):
    """Colour at 30 Hz for 1 s (red k), then, logged 0.2 s later, again with its stamps `back` periods behind where
    they would be (red 100 + k: another pass's images); depth at every third colour stamp, its stamps going back
    with the colour's (depth_restarts) or going on. late_depth: the first pass's last depth image is logged after
    the colour restarted; depth_first: each depth image of the second pass is logged before the colour of its
    stamp (its clock is seen going back first)."""
    events = []
    for k in range(30):
        events.append((T0 + k * PERIOD, "colour", k, k))
        if k % 3 == 0:
            log = T0 + k * PERIOD + 1 + (3 * PERIOD if late_depth and k == 27 else 0)
            events += [(log, "depth", k, (8, 6)), (log, "info", k, (10.0, 8, 6))]
    for j in range(30):
        log = T0 + (36 + j) * PERIOD
        k = 36 + j - back
        events.append((log, "colour", k, 100 + k))
        if j % 3 == 0:
            kd = k if depth_restarts else 36 + j
            at = log - PERIOD // 2 if depth_first else log + 1
            events += [(at, "depth", kd, (8, 6)), (at, "info", kd, (10.0, 8, 6))]
    return _write(path, events)


def test_colour_stamps_running_backwards_are_said(tmp_path):
    frames, stats = read_frames(_restart(tmp_path / "r.mcap", 20, depth_restarts=True))
    said = [w for w in stats.warnings("r.mcap") if COLOUR in w]
    assert len(said) == 1 and "earlier than the one before" in said[0], stats.warnings("r.mcap")
    assert stats.as_dict()["color_stamps_backwards"] == 1


def test_after_both_clocks_went_back_each_frame_takes_colour_of_its_own_pass(tmp_path):
    # the second pass's stamps (16 .. 45) overlap the first's last 14: each frame must take its own pass's image
    frames, stats = read_frames(_restart(tmp_path / "r.mcap", 20, depth_restarts=True))
    assert [_depth_k(f) for f in frames] == list(range(0, 30, 3)) + list(range(16, 46, 3))
    assert [_colour_k(f) for f in frames] == list(range(0, 30, 3)) + list(range(116, 146, 3))


def test_a_depth_clock_seen_going_back_before_the_colour_clock_joins_the_new_pass(tmp_path):
    frames, stats = read_frames(_restart(tmp_path / "r.mcap", 20, depth_restarts=True, depth_first=True))
    assert [_colour_k(f) for f in frames] == list(range(0, 30, 3)) + list(range(116, 146, 3))


def test_a_depth_frame_logged_after_the_colour_restart_keeps_its_own_pass(tmp_path):
    frames, stats = read_frames(_restart(tmp_path / "r.mcap", 20, depth_restarts=True, late_depth=True))
    assert [_colour_k(f) for f in frames][:10] == list(range(0, 30, 3))


def test_colour_whose_clock_alone_went_back_is_not_paired(tmp_path):
    # the depth clock goes on: the second pass's colour stamps are of another clock, its images of other instants
    frames, stats = read_frames(_restart(tmp_path / "r.mcap", 20, depth_restarts=False))
    assert [_colour_k(f) for f in frames[:10]] == list(range(0, 30, 3))
    assert all(f.color is None for f in frames[10:])
    said = [w for w in stats.warnings("r.mcap") if COLOUR in w]
    assert len(said) == 1 and "earlier than the one before" in said[0]
    assert not any("larger tolerance" in w for w in stats.warnings("r.mcap"))


# ------------------------------------------------------------------------------------ 4. rectified colour topic
def test_a_rectified_colour_topic_is_not_undistorted_again(tmp_path):
    # raw depth with a strong distortion, colour on image_rect_color in the same frame (a registered camera): the
    # colour is already undistorted onto P (= K here) and must pass unchanged
    w_, h_ = 40, 30
    K = _K(30.0, w_, h_)
    D = np.array([-0.3, 0.1, 0.0, 0.0, 0.0])
    colour = np.zeros((h_, w_, 3), np.uint8)
    colour[..., 0] = np.arange(w_, dtype=np.uint8)[None, :] * 6  # a horizontal ramp: any remap moves it
    colour[..., 1] = np.arange(h_, dtype=np.uint8)[:, None] * 8
    path = tmp_path / "rect.mcap"
    with RecordingWriter(path) as w:
        for i in range(3):
            t = T0 + i * PERIOD
            w.write_image(DEPTH, t, "cam", np.full((h_, w_), 1000, np.uint16), "16UC1")
            w.write_camera_info(INFO, t, "cam", K, w_, h_, D=D)
            w.write_image("/camera/color/image_rect_color", t, "cam", colour, "rgb8")
    frames, _ = read_frames(path)
    assert len(frames) == 3
    assert all(f.color is not None and np.array_equal(f.color, colour) for f in frames)


def test_a_raw_colour_topic_in_the_depth_frame_is_still_undistorted(tmp_path):
    w_, h_ = 40, 30
    K = _K(30.0, w_, h_)
    D = np.array([-0.3, 0.1, 0.0, 0.0, 0.0])
    colour = np.zeros((h_, w_, 3), np.uint8)
    colour[..., 0] = np.arange(w_, dtype=np.uint8)[None, :] * 6
    path = tmp_path / "raw.mcap"
    with RecordingWriter(path) as w:
        w.write_image(DEPTH, T0, "cam", np.full((h_, w_), 1000, np.uint16), "16UC1")
        w.write_camera_info(INFO, T0, "cam", K, w_, h_, D=D)
        w.write_image(COLOUR, T0, "cam", colour, "rgb8")
    (frame,), _ = read_frames(path)
    assert frame.color is not None and not np.array_equal(frame.color, colour)


# ------------------------------------------------------------------ 5. a colour camera info changing mid-stream
def test_a_colour_camera_recalibrated_mid_stream_is_projected_with_its_new_info(tmp_path):
    # a wall 1 m ahead; the colour camera (its own frame, at the depth camera's place) shifts its principal point
    # by 2 px at frame 3: each colour pixel reads 100 + 10 * (its ray's x * f), so a pixel projected with the right
    # info reads the depth pixel's own value; the first info alone put the later frames' colour 2 px beside
    f, w_, h_ = 10.0, 8, 6
    path = tmp_path / "recal_colour.mcap"
    with RecordingWriter(path) as w:
        w.write_tf(T0, [("depth", "colour", np.eye(4))], static=True)
        for k in range(6):
            t = T0 + k * PERIOD
            Kc = _K(f, w_, h_)
            Kc[0, 2] += 2.0 if k >= 3 else 0.0
            ramp = np.clip(100 + 10 * (np.arange(w_) - Kc[0, 2]), 0, 255).astype(np.uint8)
            colour = np.zeros((h_, w_, 3), np.uint8)
            colour[..., 0] = ramp[None, :]
            colour[..., 1] = 50
            w.write_image(COLOUR, t, "colour", colour, "rgb8")
            w.write_camera_info("/camera/color/camera_info", t, "colour", Kc, w_, h_)
            w.write_image(DEPTH, t, "depth", np.full((h_, w_), 1000, np.uint16), "16UC1")
            w.write_camera_info(INFO, t, "depth", _K(f, w_, h_), w_, h_)
    frames, stats = read_frames(path)
    assert stats.color_registration["mode"] == "project" and len(frames) == 6
    want = np.clip(100 + 10 * (np.arange(w_) - (w_ - 1) / 2), 0, 255)
    for frame in frames:
        seen = frame.color_mask
        assert seen is not None and seen.sum() >= 24, frame.index
        got = frame.color[..., 0].astype(float)
        np.testing.assert_allclose(got[seen], np.broadcast_to(want, (h_, w_))[seen], atol=1, err_msg=str(frame.index))


def test_colour_dropped_before_a_restart_is_no_cut_short_pairing_after_it(tmp_path):
    # 3 s of colour, then both clocks go 1.5 s back, the colour at every other stamp: the first pass's dropped
    # colour (stamps 0 .. 2 s) is not the nearer colour the second pass's frames lost
    events = []
    for k in range(90):
        events.append((T0 + k * PERIOD, "colour", k, k % 100))
        if k % 3 == 0:
            events += [(T0 + k * PERIOD + 1, "depth", k, (8, 6)), (T0 + k * PERIOD + 1, "info", k, (10.0, 8, 6))]
    for j in range(30):
        log, k = T0 + (92 + j) * PERIOD, 47 + j
        if j % 2:
            events.append((log, "colour", k, 150 + j))
        if j % 3 == 0:
            events += [(log + 1, "depth", k, (8, 6)), (log + 1, "info", k, (10.0, 8, 6))]
    frames, stats = read_frames(_write(tmp_path / "r.mcap", events))
    assert len(frames) == 40 and all(_colour_k(f) in (150 + j - 1, 150 + j + 1, 150 + j)
                                     for f, j in zip(frames[30:], range(0, 30, 3)))
    assert stats.color_cut_short == 0 and not any("no longer kept" in w for w in stats.warnings("r.mcap"))


def test_a_rectified_colour_image_on_another_pinhole_is_moved_onto_the_depth_cameras():
    from kinfu_cli.io.undistort import reproject_pinhole

    # image on P (fx 20, cx 9.5) of a 20x10 camera, given at twice the size; each pixel reads its ray's x * 100
    w_, h_ = 20, 10
    P, K = _K(20.0, w_, h_), _K(25.0, w_, h_)
    u = np.arange(2 * w_)
    ray_x = ((u + 0.5) / 2 - 0.5 - P[0, 2]) / P[0, 0]
    img = np.zeros((2 * h_, 2 * w_, 3), np.uint8)
    img[..., 0] = np.clip(np.round(128 + 100 * ray_x), 0, 255)[None, :]
    out = reproject_pinhole(img, P, K, (w_, h_))
    want = np.clip(np.round(128 + 100 * (((u + 0.5) / 2 - 0.5 - K[0, 2]) / K[0, 0])), 0, 255)
    assert out.shape == img.shape and np.abs(out[5, :, 0].astype(int) - want).max() <= 4
    assert reproject_pinhole(img, K, K, (w_, h_)) is img
