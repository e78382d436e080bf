"""volume.integrate's color_mask: pixels without a colour sample (a colour camera beside the depth camera that
does not see the point) leave the colour alone, where black samples would have darkened it."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import VolumeError
from kinfu_cli.fusion.volume import TernaryVolume


@pytest.mark.parametrize("mode", ["mean", "mode"])
def test_masked_pixels_give_no_colour(mode):
    K = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]])
    depth = np.full((48, 64), 1.0, dtype=np.float32)  # a wall 1 m in front of the camera
    red = np.zeros((48, 64, 3), dtype=np.uint8)
    red[...] = (200, 30, 30)
    mask = np.ones((48, 64), dtype=bool)
    mask[:, :32] = False  # the left half has no colour sample
    vol = TernaryVolume(size=(1.2, 1.0, 0.4), voxel_size=0.02, origin=(-0.6, -0.5, 0.8), color_mode=mode)
    for _ in range(3):
        vol.integrate(depth, K, np.eye(4), red, mask)
    _, w, c = vol.tsdf_weights(color=True)
    coloured = (w > 0) & (c.max(axis=-1) > 0)
    xs = vol.origin[0] + (np.nonzero(coloured)[0] + 0.5) * vol.voxel_size
    assert coloured.sum() > 100 and xs.min() > -0.03  # only the right half (x > 0) got colour
    assert np.all(np.abs(c[coloured].astype(int) - (200, 30, 30)).max(axis=1) <= 2)
    with pytest.raises(VolumeError, match="color_mask"):
        vol.integrate(depth, K, np.eye(4), red, mask[:, :10])
