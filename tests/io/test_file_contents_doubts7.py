"""Input files a fuzz pass found handled badly (2026-11-29): a ternary.npz of a 2048^3 grid (8 MB compressed) read
for a minute into 6.7 GB with no memory check, where a volume.npz too large is refused at once."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core import memory
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import TernaryGrid, read_ternary, save_ternary
from tests.conftest import one_line_error

GIB = 1024**3


def _npy(a) -> bytes:
    b = io.BytesIO()
    np.lib.format.write_array(b, np.asarray(a))
    return b.getvalue()


def _header_only_ternary(path: Path, shape: tuple[int, ...]) -> Path:
    """A ternary.npz whose 'ternary' member declares `shape` int8 but holds no data (what a reader allocates is
    decided by this header)."""
    head = io.BytesIO()
    np.lib.format.write_array_header_1_0(head, {"descr": "|i1", "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("ternary.npy", head.getvalue())
        z.writestr("origin.npy", _npy(np.zeros(3)))
        z.writestr("voxel_size.npy", _npy(np.float64(0.01)))
    return path


# ---------------------------------------------------------------- 1. a ternary grid too large for memory

def test_a_ternary_grid_beyond_memory_is_refused_from_its_header(tmp_path):
    path = _header_only_ternary(tmp_path / "huge.npz", (65536, 65536, 65536))
    with pytest.raises(VolumeError) as err:  # was: numpy's "Unable to allocate 256. TiB" as an unreadable file
        read_ternary(path)
    text = str(err.value)
    assert text.startswith(f"{path}: ternary grid of 65536x65536x65536 voxels would need up to 524288.0 GB (")
    assert text.endswith("GB available); expected a grid that fits in memory (fuse with a coarser voxel size or a "
                         "smaller size)")


@pytest.mark.parametrize("command", [["segment"], ["nbv", "--pois", "POIS"]])
def test_segment_and_nbv_refuse_a_2048_cubed_ternary_at_once(tmp_path, monkeypatch, command):
    path = _header_only_ternary(tmp_path / "ternary.npz", (2048, 2048, 2048))
    (tmp_path / "pois.json").write_text(json.dumps({"pois": [{"id": 0, "position": [0, 0, 0]}]}))
    monkeypatch.setattr(memory, "available_bytes", lambda: 8 * GIB)  # the labels alone would fit
    args = [str(tmp_path / "pois.json") if a == "POIS" else a for a in command]
    res = CliRunner().invoke(cli, [*args, str(path), "-o", str(tmp_path / "out"), "--quiet"])
    # the labels and one voxel-sized mask: segment on such a grid peaked at 16.9 GB
    one_line_error(res, f"{path}: ternary grid of 2048x2048x2048 voxels would need up to 16.0 GB (8.0 GB available)")


def test_the_labels_are_not_decompressed_before_the_check(tmp_path, monkeypatch):
    labels = np.zeros((64, 64, 64), np.int8)
    labels[10:20, 10:20, 10:20] = 1
    save_ternary(tmp_path / "t.npz", TernaryGrid(labels, np.zeros(3), 0.01))
    read_shapes = []
    real_read = np.lib.format.read_array

    def spy(*args, **kwargs):
        a = real_read(*args, **kwargs)
        read_shapes.append(a.shape)
        return a

    monkeypatch.setattr(np.lib.format, "read_array", spy)
    monkeypatch.setattr(memory, "available_bytes", lambda: 2 * 64**3)  # 80 % of it: under the 2 bytes a voxel
    with pytest.raises(VolumeError, match=r"t.npz: ternary grid of 64x64x64 voxels would need up to"):
        read_ternary(tmp_path / "t.npz")
    assert (64, 64, 64) not in read_shapes
    monkeypatch.setattr(memory, "available_bytes", lambda: 3 * 64**3)  # fits: read as before
    grid = read_ternary(tmp_path / "t.npz")
    assert grid.shape == (64, 64, 64) and grid.counts()["occupied"] == 1000 and (64, 64, 64) in read_shapes


def test_labels_of_another_integer_type_count_their_int8_copy(tmp_path, monkeypatch):
    voxels = 32**3
    monkeypatch.setattr(memory, "available_bytes", lambda: int(voxels * 9.5 / memory.USABLE_FRACTION))
    np.savez(tmp_path / "i64.npz", ternary=np.zeros((32, 32, 32), np.int64), origin=np.zeros(3), voxel_size=0.01)
    with pytest.raises(VolumeError, match="i64.npz: ternary grid of 32x32x32 voxels would need"):
        read_ternary(tmp_path / "i64.npz")  # 8 bytes a voxel read, 1 for the int8 copy, 1 for a mask: 10 > 9.5
    np.savez(tmp_path / "i32.npz", ternary=np.zeros((32, 32, 32), np.int32), origin=np.zeros(3), voxel_size=0.01)
    assert read_ternary(tmp_path / "i32.npz").labels.dtype == np.int8  # 6 bytes a voxel: fits


def test_the_volume_check_keeps_its_message():
    from kinfu_cli.fusion.volume import TernaryVolume

    with pytest.raises(VolumeError) as err:
        TernaryVolume(size=20.0, voxel_size=0.002)
    assert err.value.parameter == "voxel_size/size"
    assert err.value.detail.startswith("volume of 10000x10000x10000 voxels at 2.00 mm would need up to ")
    assert err.value.detail.endswith("GB available); use a coarser voxel size or a smaller size")
