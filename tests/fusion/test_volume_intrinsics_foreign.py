"""volume_intrinsics (what `kinfu nbv` reads first) on a readable .npz that is neither a volume.npz nor a
ternary.npz: a VolumeError naming the file (it was an AttributeError traceback)."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import VolumeError
from kinfu_cli.fusion.volume import volume_intrinsics


def test_an_npz_of_other_arrays_is_a_volume_error(tmp_path):
    path = tmp_path / "volume.npz"
    np.savez(path, pool_v=np.zeros((2, 512), np.int16))
    with pytest.raises(VolumeError) as err:
        volume_intrinsics(path)
    assert str(path) in str(err.value) and "not a kinfu volume.npz or ternary.npz" in str(err.value)
