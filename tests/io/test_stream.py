"""Streaming: memory while iterating frames does not grow with the number of messages."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter

W, H = 80, 60


def _write(path, n):
    K = np.array([[60.0, 0, 39.5], [0, 60.0, 29.5], [0, 0, 1]])
    rng = np.random.default_rng(0)
    with RecordingWriter(path) as w:
        for i in range(n):
            t = 10**18 + i * 33_333_333
            w.write_image("/camera/depth/image_raw", t, "cam", rng.integers(1, 5000, (H, W)).astype(np.uint16),
                          "16UC1")
            w.write_image("/camera/color/image_raw", t + 1000, "cam", rng.integers(0, 255, (H, W, 3)).astype(np.uint8),
                          "rgb8")
            w.write_camera_info("/camera/depth/camera_info", t, "cam", K, W, H)
    return path


def _peak_while_iterating(path) -> tuple[int, int]:
    with open_recording(path) as rec:
        rec.topics  # noqa: B018 - index and summary read before measuring
        tracemalloc.start()
        n = 0
        checksum = 0.0
        for f in iter_frames(rec, pose_source="none"):
            n += 1
            checksum += float(f.depth[0, 0])
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return n, peak


@pytest.mark.parametrize("suffix", [".mcap", ".bag", "_ros2"])
def test_frame_iteration_memory_is_flat(tmp_path, suffix):
    # both recordings span several 1 MB chunks (~43 frames each); memory may hold a chunk, not the recording
    small = _write(tmp_path / f"small{suffix}", 150)
    large = _write(tmp_path / f"large{suffix}", 450)
    n_small, peak_small = _peak_while_iterating(small)
    n_large, peak_large = _peak_while_iterating(large)
    assert (n_small, n_large) == (150, 450)
    decoded_large = 450 * H * W * (4 + 3)  # holding every decoded frame would take 15 MB
    assert peak_large < 1.15 * peak_small + 300_000, (peak_small, peak_large)
    assert peak_large < 0.4 * decoded_large, (peak_large, decoded_large)
