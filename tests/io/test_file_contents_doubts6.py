"""Input files (not recordings) a fuzz pass found handled badly (2026-11-29): tracebacks on a TUM stamp beyond
int64 nanoseconds, a segments.json count or id that is not a number, a PLY whose x is a list, a mesh whose faces
index past its vertices; errors naming options for a volume file's own grid, numpy's pickle message for a file
that is not an npz, a ternary voxel of a nanometre accepted, a --init volume whose truncation cannot hold a
surface fused into."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import TrajectoryError, VolumeError
from kinfu_cli.core.grid import TernaryGrid, read_ternary, save_ternary
from kinfu_cli.fusion.volume import TernaryVolume, load_volume
from kinfu_cli.grasp.plan import GraspError, _segment_id
from kinfu_cli.io.labelled_cloud import LabelsFileError, read_labelled_cloud
from kinfu_cli.io.tum import read_tum
from kinfu_cli.localization.mesh_model import LocalizationError, check_mesh
from kinfu_cli.localization.points import read_segment_points
from tests.conftest import one_line_error
from tests.recordings import make_recording


@pytest.mark.parametrize("stamp", ["1e20", "-1e20"])
def test_a_tum_stamp_beyond_nanosecond_range_is_named(tmp_path, stamp):
    path = tmp_path / "trajectory.tum"
    path.write_text(f"0 0 0 0 0 0 0 1\n{stamp} 0 0 1 0 0 0 1\n")
    with pytest.raises(TrajectoryError, match=rf"trajectory.tum:2: timestamp {stamp} s is beyond"):
        read_tum(path)
    path.write_text("-5.5 0 0 1 0 0 0 1\n1700000000.25 0 0 1 0 0 0 1\n")  # relative or Unix seconds: read
    assert read_tum(path)[0].tolist() == [-5_500_000_000, 1_700_000_000_250_000_000]


@pytest.mark.parametrize("count", [None, "many", float("inf"), -3])
def test_a_segment_count_that_is_not_a_count_is_named(tmp_path, count):
    seg = {"id": 1, "kind": "object"} | ({} if count is None else {"point_count": count})
    (tmp_path / "segments.json").write_text(json.dumps({"segments": [seg]}))
    with pytest.raises(LocalizationError, match=r"segments.json: segment 1's point_count is"):
        read_segment_points(tmp_path / "segments.json", 1)


def test_an_infinite_segment_id_is_named(tmp_path):
    (tmp_path / "segments.json").write_text('{"segments": [{"id": Infinity, "kind": "object"}]}')
    with pytest.raises(LocalizationError, match="not a kinfu segment segments.json"):
        read_segment_points(tmp_path / "segments.json", 1)
    with pytest.raises(GraspError, match=r"segments\[0\].id is inf, expected an integer"):
        _segment_id({"id": float("inf")}, 0, "segments.json")


def test_a_ply_whose_coordinates_are_lists_is_named(tmp_path):
    path = tmp_path / "labels.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty list uchar float x\nproperty float y\n"
                    "property float z\nproperty int label\nend_header\n2 1 2 0 0 1\n1 1 0 0 1\n")
    with pytest.raises(LabelsFileError, match="labels.ply: vertex x, y, z are not numbers"):
        read_labelled_cloud(path)


def test_mesh_faces_past_the_vertices_are_named():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    check_mesh(v, f, "tetra.ply")  # closed: fine
    with pytest.raises(LocalizationError, match=r"tetra.ply: mesh faces index vertices 0 to 1000003, but it has 4"):
        check_mesh(v, f + np.array([[0, 0, 10**6]]), "tetra.ply")


def test_a_volume_files_own_grid_is_blamed_on_the_file_not_on_options(tmp_path):
    vol = TernaryVolume(size=0.4, voxel_size=0.02)
    vol.save(tmp_path / "volume.npz")
    z = np.load(tmp_path / "volume.npz")
    arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays["meta"]))
    meta["shape"] = [65536, 65536, 8]
    arrays |= {"meta": np.array(json.dumps(meta)), "block_idx": np.full((8192, 8192, 1), -1, np.int32),
               "block_w": np.zeros((8192, 8192, 1), np.uint8)}
    np.savez_compressed(tmp_path / "huge.npz", **arrays)
    with pytest.raises(VolumeError) as err:
        load_volume(tmp_path / "huge.npz")
    assert str(err.value).startswith(f"{tmp_path / 'huge.npz'}: volume of 65536x65536x8 voxels") and \
        err.value.parameter is None


def test_a_ternary_file_is_checked_like_a_volume_file(tmp_path):
    (tmp_path / "text.npz").write_text("hello, not a zip\n")
    with pytest.raises(VolumeError, match=r"text.npz: not an .npz file"):
        read_ternary(tmp_path / "text.npz")
    save_ternary(tmp_path / "t.npz", TernaryGrid(np.zeros((4, 4, 4), np.int8), np.zeros(3), 1e-9))
    with pytest.raises(VolumeError, match=r"t.npz: 'voxel_size' is 1e-09, expected a voxel edge of 0.0001 to 1000 m"):
        read_ternary(tmp_path / "t.npz")


def test_init_refuses_a_volume_whose_truncation_holds_no_surface(tmp_path):
    rec = make_recording(tmp_path / "rec.mcap")
    vol = TernaryVolume(size=1.0, voxel_size=0.02)
    vol.truncation = 1e-9  # read back as it was written; fusing into it would lose every surface
    vol.save(tmp_path / "volume.npz")
    res = CliRunner().invoke(cli, ["fuse", str(rec), "--init", str(tmp_path / "volume.npz"), "-o",
                                   str(tmp_path / "out"), "--quiet"])
    one_line_error(res, "volume.npz: its truncation 1e-09 m is under half its 0.02 m voxel")
    assert not (tmp_path / "out").exists()


def test_spheres_to_forget_outside_the_grid_are_said(tmp_path):
    # POIs 100 km away (another scene's, another frame's) forgot nothing with exit 0 and no word
    rec = make_recording(tmp_path / "rec.mcap")
    (tmp_path / "far.json").write_text(json.dumps({"pois": [{"id": 0, "position": [1e5, 1e5, 1e5]}]}))
    (tmp_path / "none.json").write_text(json.dumps({"pois": []}))
    res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(tmp_path / "a"), "--quiet", "--clear-pois",
                                   str(tmp_path / "far.json"), "--clear-sphere", "0.3,0,1,0.05"])
    assert res.exit_code == 0, res.output
    said = [line for line in res.output.splitlines() if "nothing was forgotten" in line]
    assert len(said) == 1 and "far.json#0: the sphere to forget at (1e+05, 1e+05, 1e+05) m" in said[0]
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    assert any("far.json#0" in w for w in report["warnings"])
    res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(tmp_path / "b"), "--quiet", "--clear-pois",
                                   str(tmp_path / "none.json")])
    assert res.exit_code == 0 and "none.json: holds no POI, so nothing was forgotten" in res.output
