"""Colour images as webcams and machine-vision cameras publish them: packed YUV 4:2:2, Bayer mosaics, 16 bits."""

from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.messages import decode_color

H, W = 8, 12
RGB = np.zeros((H, W, 3), np.uint8)
RGB[:, :6] = (200, 40, 30)  # red left half
RGB[:, 6:] = (30, 60, 200)  # blue right half


def _image(array, encoding):
    a = np.ascontiguousarray(array)
    return SimpleNamespace(height=H, width=W, step=a.nbytes // H, encoding=encoding, is_bigendian=0,
                           data=a.tobytes())


def _mosaic(pattern):
    """The camera's raw image: one channel per pixel, the 2x2 `pattern` (e.g. 'rggb') tiled."""
    ch = {"r": 0, "g": 1, "b": 2}
    raw = np.zeros((H, W), np.uint8)
    for k, c in enumerate(pattern):
        dy, dx = divmod(k, 2)
        raw[dy::2, dx::2] = RGB[dy::2, dx::2, ch[c]]
    return raw


@pytest.mark.parametrize("pattern", ["rggb", "bggr", "gbrg", "grbg"])
def test_bayer_mosaics_give_the_scene_colours(pattern):
    got = decode_color(_image(_mosaic(pattern), f"bayer_{pattern}8"), "/cam")
    inner = np.abs(got[2:-2, 2:4].astype(int) - RGB[2:-2, 2:4]).max()  # away from the edge between the halves
    assert inner <= 2, (pattern, got[3, 2], RGB[3, 2])


@pytest.mark.parametrize("encoding", ["yuv422", "yuv422_yuy2"])
def test_packed_yuv(encoding):
    r, g, b = (RGB[..., c].astype(float) for c in range(3))  # BT.601 video range, as cameras and cv_bridge
    yuv = np.stack([16 + 0.257 * r + 0.504 * g + 0.098 * b, 128 - 0.148 * r - 0.291 * g + 0.439 * b,
                    128 + 0.439 * r - 0.368 * g - 0.071 * b], -1).round().astype(np.int32)
    packed = np.zeros((H, W, 2), np.uint8)  # 4:2:2: each pixel its Y, pairs share U and V
    y, u, v = yuv[..., 0], yuv[..., 1], yuv[..., 2]
    if encoding == "yuv422":  # UYVY
        packed[:, 0::2, 0], packed[:, 1::2, 0] = u[:, 0::2], v[:, 0::2]
        packed[..., 1] = y
    else:  # YUY2: Y U Y V
        packed[..., 0] = y
        packed[:, 0::2, 1], packed[:, 1::2, 1] = u[:, 0::2], v[:, 0::2]
    got = decode_color(_image(packed, encoding), "/cam")
    assert np.abs(got.astype(int) - RGB).max() <= 3


def test_16_bit_and_unknown():
    got = decode_color(_image(RGB.astype(np.uint16) * 257, "bgr16"), "/cam")
    assert np.array_equal(got, RGB[:, :, ::-1])
    assert np.array_equal(decode_color(_image(RGB[:, :, 0].astype(np.uint16) * 257, "mono16"), "/cam")[..., 1],
                          RGB[:, :, 0])
    with pytest.raises(RecordingError, match="/cam: colour encoding 'nv21'"):
        decode_color(_image(RGB, "nv21"), "/cam")
