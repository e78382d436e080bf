"""Input files a fuzz pass found handled badly (2026-11-29): a ternary.npz of a 2048^3 grid (8 MB compressed) read
for a minute into 6.7 GB with no memory check, where a volume.npz too large is refused at once; a volume.npz whose
pool_v is not int16 was cast silently (40000 became -25536) and weights above its max_weight were fused on; eval
fusion scored a mesh whose faces index past its vertices (localize refused it)."""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core import memory
from kinfu_cli.core.errors import RecordingError, VolumeError
from kinfu_cli.core.grid import TernaryGrid, read_ternary, save_ternary
from kinfu_cli.evaluation.reconstruction import read_mesh_arrays
from kinfu_cli.fusion.volume import load_volume
from kinfu_cli.localization.mesh_model import LocalizationError, check_mesh
from kinfu_cli.sim.scenario import _read_mesh
from tests.conftest import one_line_error, small_tabletop_volume

GIB = 1024**3
OBJ4 = Path(__file__).resolve().parents[2] / "sample_data" / "tabletop" / "ground_truth" / "objects" / "obj4.ply"


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


# ---------------------------------------------------------------- 2, 3. pools of another type, weights too high

@pytest.fixture(scope="module")
def saved_volume(tmp_path_factory):
    """A fused volume with max_weight 2 whose weights reach it (3 frames), saved by kinfu, and its arrays."""
    vol = small_tabletop_volume(max_weight=2, frames=3)
    path = tmp_path_factory.mktemp("vol") / "volume.npz"
    vol.save(path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    assert arrays["pool_v"].dtype == np.int16 and len(arrays["pool_v"]) > 10
    assert int(arrays["pool_w"].max()) == 2 and int(arrays["block_w"].max()) == 2
    return path, arrays


def _edited(saved_volume, path: Path, **changes) -> Path:
    _, arrays = saved_volume
    np.savez_compressed(path, **(arrays | changes))
    return path


def test_a_volume_written_by_kinfu_is_read_with_weights_at_its_max(saved_volume):
    vol = load_volume(saved_volume[0])
    assert vol.max_weight == 2 and int(vol.pool_w[: vol.n_used].max()) == 2 and vol.pool_v.dtype == np.int16


@pytest.mark.parametrize("dtype", [np.int32, np.int64, np.uint16, np.int8])
def test_a_distance_pool_that_is_not_int16_is_refused(saved_volume, tmp_path, dtype):
    pv = saved_volume[1]["pool_v"]
    if np.dtype(dtype).itemsize > 2:
        pv = pv.astype(dtype)
        pv[0, 0] = 40000  # was cast to -25536 (occupied) without a word
    path = _edited(saved_volume, tmp_path / "volume.npz", pool_v=pv.astype(dtype))
    with pytest.raises(VolumeError) as err:
        load_volume(path)
    assert str(err.value) == (f"{path}: 'pool_v' is {np.dtype(dtype).name}, expected int16 (truncated distances "
                              f"times 32767, as kinfu writes them)")


@pytest.mark.parametrize("member,value,dtype", [("pool_w", 3, np.uint8), ("pool_w", 255, np.uint8),
                                                ("pool_w", -1, np.int16), ("block_w", 200, np.uint8)])
def test_weights_outside_max_weight_are_refused(saved_volume, tmp_path, member, value, dtype):
    w = saved_volume[1][member].astype(dtype)
    w.flat[np.flatnonzero(w)[0]] = value
    path = _edited(saved_volume, tmp_path / "volume.npz", **{member: w})
    with pytest.raises(VolumeError) as err:
        load_volume(path)
    lo, hi = min(0, value), max(2, value)
    assert str(err.value) == f"{path}: '{member}' holds weights {lo} to {hi}, expected 0 to the volume's max_weight 2"


def test_segment_names_the_bad_pool_in_one_line(saved_volume, tmp_path):
    w = saved_volume[1]["pool_w"].copy()
    w[0, 0] = 100
    path = _edited(saved_volume, tmp_path / "volume.npz", pool_w=w)
    res = CliRunner().invoke(cli, ["segment", str(path), "-o", str(tmp_path / "seg"), "--quiet"])
    one_line_error(res, f"{path}: 'pool_w' holds weights 0 to 100, expected 0 to the volume's max_weight 2")
    assert not (tmp_path / "seg").exists()


# ---------------------------------------------------------------- 4. mesh faces past the vertices

def _ascii_mesh(path: Path, vertices, faces) -> Path:
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}", "property float x", "property float y",
             "property float z", f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(map(str, v)) for v in vertices] + [f"3 {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


TETRA_V = [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
TETRA_F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]


def test_eval_fusion_refuses_mesh_faces_past_the_vertices(sample_dir, tmp_path):
    bad = _ascii_mesh(tmp_path / "mesh.ply", TETRA_V, TETRA_F[:3] + [[1, 2, 1000]])
    with pytest.raises(VolumeError) as err:
        read_mesh_arrays(bad)
    assert str(err.value) == f"{bad}: mesh faces index vertices 0 to 1000, but it has 4 (a damaged file?)"
    with pytest.raises(LocalizationError) as same:  # localize's model check: the same words
        check_mesh(np.array(TETRA_V, float), np.array(TETRA_F[:3] + [[1, 2, 1000]]), str(bad))
    assert str(same.value) == str(err.value)
    res = CliRunner().invoke(cli, ["eval", "fusion", str(bad), "--ground-truth", str(sample_dir), "-o",
                                   str(tmp_path / "fusion.json"), "--quiet"])
    one_line_error(res, f"{bad}: mesh faces index vertices 0 to 1000, but it has 4 (a damaged file?)")
    assert not (tmp_path / "fusion.json").exists()


def test_a_whole_mesh_and_a_point_cloud_still_read(tmp_path):
    v, f = read_mesh_arrays(_ascii_mesh(tmp_path / "tetra.ply", TETRA_V, TETRA_F))
    assert len(v) == 4 and f.tolist() == TETRA_F
    v, f = read_mesh_arrays(shutil.copy(OBJ4, tmp_path / "obj4.ply"))
    assert len(v) == 42 and len(f) == 80
    v, f = read_mesh_arrays(_ascii_mesh(tmp_path / "cloud.ply", TETRA_V, []))
    assert len(v) == 4 and len(f) == 0


def test_a_ground_truth_mesh_with_faces_past_its_vertices_is_named(tmp_path):
    bad = _ascii_mesh(tmp_path / "scene_after.ply", TETRA_V, [[0, 1, -2]] + TETRA_F[1:])
    with pytest.raises(RecordingError) as err:
        _read_mesh(bad)
    assert str(err.value) == f"{bad}: mesh faces index vertices -2 to 3, but it has 4 (a damaged file?)"
    assert len(_read_mesh(_ascii_mesh(tmp_path / "ok.ply", TETRA_V, TETRA_F)).triangles) == 4


def test_eval_nbv_refuses_a_bare_mesh_scene_with_faces_past_its_vertices(tmp_path):
    from kinfu_cli.evaluation.nbv_loop import LoopConfig, load_scene

    bad = _ascii_mesh(tmp_path / "scene.ply", TETRA_V, TETRA_F[:3] + [[1, 2, 7]])
    with pytest.raises(RecordingError) as err:
        load_scene(bad, LoopConfig(poi=(0.0, 0.0, 0.05)))
    assert str(err.value) == f"{bad}: mesh faces index vertices 0 to 7, but it has 4 (a damaged file?)"
    scene = load_scene(_ascii_mesh(tmp_path / "ok.ply", TETRA_V, TETRA_F), LoopConfig(poi=(0.0, 0.0, 0.05)))
    assert len(scene.after.triangles) == 4
