"""An organized cloud whose bytes are not what its header says (is_bigendian set on little-endian data, random
bytes): signalling NaNs and 1e38 values, read without a numpy warning on stderr; the cloud is refused as no
pinhole projection (a RecordingError naming the topic), never decoded into a depth image silently."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.pointcloud2 import decode_cloud, fit_intrinsics, organized_cloud, pinhole_rms

K = np.array([[40.0, 0, 15.5], [0, 40.0, 11.5], [0, 0, 1]])


def _msg(data: bytes, big: bool, step: int = 16) -> SimpleNamespace:
    fields = [SimpleNamespace(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]
    return SimpleNamespace(height=24, width=32, point_step=step, row_step=step * 32, is_bigendian=big,
                           is_dense=False, fields=fields, data=data)


def _swapped_flag():
    arr = organized_cloud(np.full((24, 32), 0.9), K)
    return _msg(arr.tobytes(), big=True, step=arr.dtype.itemsize)


def _random():
    return _msg(np.random.default_rng(3).integers(0, 256, 24 * 32 * 16, dtype=np.uint8).tobytes(), big=False)


@pytest.mark.parametrize("make", [_swapped_flag, _random])
def test_garbage_bits_are_refused_quietly(make):
    msg = make()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "invalid value encountered in cast" reached stderr
        depth, _ = decode_cloud(msg, "/cloud")
        assert depth.dtype == np.float32 and np.all(np.isfinite(depth)) and np.all(depth >= 0)
        assert pinhole_rms(msg, K, "/cloud") > 1.0
        with pytest.raises(RecordingError, match="/cloud"):
            fit_intrinsics(msg, "/cloud")
