"""`ternary.npz` carries the depth intrinsics it was fused with, so `kinfu nbv` on one plans with that camera."""

import numpy as np
import pytest

from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import TernaryGrid, read_ternary, save_ternary
from kinfu_cli.fusion.volume import volume_intrinsics

K = {"fx": 525.0, "fy": 526.0, "cx": 319.5, "cy": 239.5, "width": 640, "height": 480}


def _grid(**kw) -> TernaryGrid:
    return TernaryGrid(np.zeros((4, 5, 6), np.int8), np.zeros(3), 0.01, "world", np.array([0, 0, 1.0]), **kw)


def test_intrinsics_round_trip(tmp_path):
    save_ternary(tmp_path / "t.npz", _grid(intrinsics=K))
    assert read_ternary(tmp_path / "t.npz").intrinsics == K
    assert volume_intrinsics(tmp_path / "t.npz") == K


def test_older_ternary_files_have_none(tmp_path):
    save_ternary(tmp_path / "t.npz", _grid())
    assert volume_intrinsics(tmp_path / "t.npz") is None


def test_malformed_intrinsics_name_the_file(tmp_path):
    np.savez(tmp_path / "bad.npz", ternary=np.zeros((2, 2, 2), np.int8), origin=np.zeros(3), voxel_size=0.01,
             intrinsics=np.array([525.0, -1, 1, 1, 640, 480]))
    with pytest.raises(VolumeError, match="bad.npz: 'intrinsics' out of range"):
        read_ternary(tmp_path / "bad.npz")
