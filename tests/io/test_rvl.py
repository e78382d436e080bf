"""compressedDepth RVL (ROS 2's faster compressed_depth_image_transport format): the codec against a stream worked
out by hand from Wilson's algorithm, round trips, the depth decoder for 16UC1 and 32FC1, and corrupt data."""

from __future__ import annotations

import struct
from types import SimpleNamespace

import numpy as np
import pytest

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.messages import decode_depth
from kinfu_cli.io.rvl import HEADER_BYTES, decode_rvl, encode_rvl


def test_stream_as_the_paper_writes_it():
    """[0, 0, 5]: 2 zeros (nibble 2), 1 non-zero (1), zigzag(5) = 10 = 0b1_010 in 3-bit groups, lowest first
    (0xA: 2 and 'more', then 1): nibbles 2 1 A 1, packed from the top of a little-endian word."""
    data = encode_rvl(np.array([[0, 0, 5]], np.uint16))
    assert data[HEADER_BYTES:] == struct.pack("<II", 3, 1) + bytes.fromhex("0000a121")
    img, _ = decode_rvl(data)
    assert img.tolist() == [[0, 0, 5]]


def test_round_trips():
    rng = np.random.default_rng(0)
    for trial in range(60):
        h, w = (int(v) for v in rng.integers(1, 30, 2))
        img = rng.integers(0, 65536, (h, w)).astype(np.uint16)
        img[rng.random((h, w)) < rng.random()] = 0
        if trial % 3 == 0:  # smooth rows, as depth is: small differences
            img = np.cumsum(rng.integers(-3, 4, (h, w)), axis=1).astype(np.uint16)
        back, _ = decode_rvl(encode_rvl(img))
        assert np.array_equal(back, img)
    assert np.array_equal(decode_rvl(encode_rvl(np.zeros((48, 64), np.uint16)))[0], np.zeros((48, 64)))


def _msg(fmt, data):
    return SimpleNamespace(format=fmt, data=np.frombuffer(data, np.uint8))


def test_depth_from_16uc1_and_32fc1_rvl():
    rng = np.random.default_rng(1)
    mm = rng.integers(400, 4000, (24, 32)).astype(np.uint16)
    mm[:, :4] = 0
    depth = decode_depth(_msg("16UC1; compressedDepth rvl", encode_rvl(mm)), "/d")
    np.testing.assert_array_equal(depth, mm.astype(np.float32) * np.float32(0.001))
    # 32FC1: inverse depth quantised as compressed_depth_image_transport does (z0 = 0.01 m, max 10 m)
    z = rng.uniform(0.4, 4.0, (24, 32)).astype(np.float32)
    a = np.float32(0.01 * 1.01)
    b = np.float32(1.0 - a / 10.0)
    inv = (a / z + b).astype(np.uint16)
    inv[0, 0] = 0  # no reading
    got = decode_depth(_msg("32FC1; compressedDepth rvl", encode_rvl(inv, struct.pack("<iff", 0, a, b))), "/d")
    assert got[0, 0] == 0
    step = z ** 2 / a  # one inverse-depth step in metres
    assert np.all(np.abs(got - z)[1:] <= step[1:] * 1.01)


@pytest.mark.parametrize("cut, why", [(lambda d: d[:-4], "ends before"), (lambda d: d[:HEADER_BYTES + 4], "header"),
                                      (lambda d: d[:HEADER_BYTES] + struct.pack("<II", 0, 5) + d[20:], "size 0x5"),
                                      (lambda d: d[:HEADER_BYTES] + struct.pack("<II", 99999, 99999) + d[20:],
                                       "99999x99999")])
def test_corrupt_rvl_is_a_recording_error(cut, why):
    data = encode_rvl(np.arange(1, 401, dtype=np.uint16).reshape(20, 20))
    with pytest.raises(RecordingError, match=f"/depth: compressedDepth RVL data: .*{why}"):
        decode_depth(_msg("16UC1; compressedDepth rvl", cut(data)), "/depth")
