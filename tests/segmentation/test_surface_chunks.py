"""The surface of a fused volume read chunk by chunk only around its surface blocks is the surface read from whole
chunks: the same vertices, bit for bit (speed for `kinfu segment`, not a different answer)."""

from __future__ import annotations

import numpy as np
from conftest import small_tabletop_volume

from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.segmentation.surface import surface_from_volume


class _WholeChunks:
    """The volume without `surface_blocks`: the surface is then read from every chunk with an allocated block,
    whole (as before chunks were trimmed)."""

    def __init__(self, volume):
        self._volume = volume

    def __getattr__(self, name):
        if name == "surface_blocks":
            raise AttributeError(name)
        return getattr(self._volume, name)


def test_trimmed_chunks_give_the_vertices_of_whole_chunks(monkeypatch):
    vol = small_tabletop_volume(5, voxel=0.005, truncation=0.02, frames=4, noise=True)
    read = []
    real = TernaryVolume.tsdf_weights

    def counted(self, lo=None, hi=None, color=False):
        read.append(int(np.prod(np.asarray(hi) - np.asarray(lo))))
        return real(self, lo, hi, color)

    monkeypatch.setattr(TernaryVolume, "tsdf_weights", counted)
    fast = surface_from_volume(vol, resolution=None)
    read_fast = sum(read)
    read.clear()
    whole = surface_from_volume(_WholeChunks(vol), resolution=None)
    assert len(fast) > 5000
    assert np.array_equal(fast.points, whole.points) and np.array_equal(fast.normals, whole.normals)
    assert np.array_equal(fast.colors, whole.colors)
    assert read_fast < 0.9 * sum(read)  # and fewer voxels were copied densely (0.3 on the synth 512^3 volume)
