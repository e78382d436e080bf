"""RVL, the lossless depth codec of Wilson ("Fast lossless depth image compression", ISS 2017), as ROS's
compressed_depth_image_transport writes it (format "16UC1; compressedDepth rvl" or "32FC1; compressedDepth rvl",
the faster choice on ROS 2 since Humble). No library on PyPI reads it, so it is here, in numba.

The stream is 32-bit little-endian words of eight 4-bit nibbles, most significant first. A value is written in
3-bit groups, lowest first, each nibble's top bit saying that another group follows. The image, row by row, is
runs: a count of zeros, a count of non-zeros, then each non-zero as its zigzag-coded difference from the previous
non-zero (which starts at 0 and carries over runs).

The message data: a 12-byte header (int32 format, float32 quantisation a and b; 32FC1 stores a / (depth) + b),
uint32 width, uint32 height, then the stream.
"""

from __future__ import annotations

import struct

import numpy as np
from numba import njit

HEADER_BYTES = 12  # compressed_depth_image_transport's ConfigHeader
MAX_PIXELS = 1 << 26  # 64 M pixels: larger sizes are a corrupt header, not an image

_OK, _SHORT, _OVERRUN, _TOO_LONG = 0, 1, 2, 3
_WHY = {_SHORT: "the stream ends before the image does", _OVERRUN: "a run goes past the image's last pixel",
        _TOO_LONG: "a value runs over 11 nibbles"}


@njit(cache=True)
def _decode(words, n_pixels):
    """(uint16 (n_pixels,), status): status _OK or why the stream is corrupt."""
    out = np.zeros(n_pixels, dtype=np.uint16)
    n_words = words.shape[0]
    w = 0  # next word
    word = np.uint32(0)
    left = 0  # nibbles left in `word`
    pos = 0
    previous = np.int64(0)
    run = 0  # 0: a zeros count is next, 1: a non-zeros count, 2: values
    todo = 0
    while pos < n_pixels:  # a run's count is checked against the pixels left when it is read
        value = np.int64(0)
        shift = 0
        while True:
            if left == 0:
                if w >= n_words:
                    return out, _SHORT
                word = words[w]
                w += 1
                left = 8
            nibble = (word >> np.uint32(28)) & np.uint32(15)
            word = (word << np.uint32(4)) & np.uint32(0xFFFFFFFF)
            left -= 1
            value |= np.int64(nibble & np.uint32(7)) << shift
            shift += 3
            if nibble & np.uint32(8) == 0:
                break
            if shift > 30:
                return out, _TOO_LONG
        if run == 0:
            if pos + value > n_pixels:
                return out, _OVERRUN
            pos += value  # zeros: out is zero already
            run = 1
        elif run == 1:
            if pos + value > n_pixels:
                return out, _OVERRUN
            todo = value
            run = 2 if todo > 0 else 0
        else:
            delta = (value >> 1) ^ -(value & 1)
            previous = (previous + delta) & 0xFFFF
            out[pos] = previous
            pos += 1
            todo -= 1
            if todo == 0:
                run = 0
    return out, _OK


@njit(cache=True)
def _encode(values):
    """uint32 words of the RVL stream of uint16 `values` (the encoder of the paper; tests and round trips)."""
    n = values.shape[0]
    words = np.zeros(n + 8, dtype=np.uint32)  # the worst case is 6 nibbles a pixel (a 17-bit zigzag difference)
    state = np.zeros(3, dtype=np.int64)  # next word, current word, nibbles in it

    i = 0
    previous = np.int64(0)
    while i < n:
        zeros = 0
        while i + zeros < n and values[i + zeros] == 0:
            zeros += 1
        _put(words, state, zeros)
        i += zeros
        nonzeros = 0
        while i + nonzeros < n and values[i + nonzeros] != 0:
            nonzeros += 1
        _put(words, state, nonzeros)
        for _ in range(nonzeros):
            current = np.int64(values[i])
            delta = current - previous
            _put(words, state, (delta << 1) ^ (delta >> 63))
            previous = current
            i += 1
    if state[2] > 0:
        words[state[0]] = np.uint32((state[1] << (4 * (8 - state[2]))) & 0xFFFFFFFF)
        state[0] += 1
    return words[: state[0]]


@njit(cache=True)
def _put(words, state, value):
    while True:
        nibble = value & 7
        value >>= 3
        if value:
            nibble |= 8
        state[1] = ((state[1] << 4) | nibble) & 0xFFFFFFFF
        state[2] += 1
        if state[2] == 8:
            if state[0] >= words.shape[0]:  # never: the buffer holds the worst case
                return
            words[state[0]] = np.uint32(state[1])
            state[0] += 1
            state[1] = 0
            state[2] = 0
        if not value:
            return


def decode_rvl(data: bytes) -> tuple[np.ndarray, bytes]:
    """(uint16 (height, width) image, the 12-byte header) of a compressedDepth RVL message's data; ValueError
    saying what is wrong with corrupt data."""
    if len(data) < HEADER_BYTES + 8:
        raise ValueError(f"{len(data)} bytes, less than the {HEADER_BYTES + 8}-byte header and image size")
    width, height = struct.unpack_from("<II", data, HEADER_BYTES)
    if width == 0 or height == 0 or width * height > MAX_PIXELS:
        raise ValueError(f"image size {width}x{height} in its header")
    stream = data[HEADER_BYTES + 8:]
    stream += b"\0" * (-len(stream) % 4)
    img, status = _decode(np.frombuffer(stream, dtype="<u4").astype(np.uint32), width * height)
    if status != _OK:
        raise ValueError(f"corrupt RVL stream for {width}x{height}: {_WHY[status]}")
    return img.reshape(height, width), data[:HEADER_BYTES]


def encode_rvl(image: np.ndarray, header: bytes = b"\0" * HEADER_BYTES) -> bytes:
    """A compressedDepth RVL message's data for a uint16 (height, width) image."""
    img = np.ascontiguousarray(image, dtype=np.uint16)
    h, w = img.shape
    words = _encode(img.reshape(-1))
    return bytes(header) + struct.pack("<II", w, h) + words.astype("<u4").tobytes()
