"""A mesh.ply cut short (a copy or write interrupted) was scored without a word: open3d keeps the header's vertex
count and reads what is there, and half a mesh scored completeness 0.50 instead of 0.86. It is now an error naming
the file; whole files, binary or ASCII, read as before."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from kinfu_cli.core.errors import VolumeError
from kinfu_cli.evaluation.reconstruction import read_mesh_arrays
from kinfu_cli.io.ply_size import ply_cut_short

MESH = Path(__file__).resolve().parents[2] / "sample_data" / "tabletop" / "ground_truth" / "objects" / "obj4.ply"


def test_a_binary_mesh_cut_short_is_refused(tmp_path):
    whole = shutil.copy(MESH, tmp_path / "mesh.ply")
    v, f = read_mesh_arrays(whole)
    assert len(v) == 42 and len(f) == 80 and ply_cut_short(Path(whole)) is None
    data = Path(whole).read_bytes()
    for keep in (len(data) - 1, len(data) // 2):
        (tmp_path / "cut.ply").write_bytes(data[:keep])
        with pytest.raises(VolumeError, match=r"cut.ply: PLY file cut short \(the header declares 122 rows"):
            read_mesh_arrays(tmp_path / "cut.ply")


def test_an_ascii_ply_with_fewer_rows_than_declared_is_refused(tmp_path):
    head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    (tmp_path / "a.ply").write_text(head + "0 0 0\n1 0 0\n0 1 0\n")
    assert ply_cut_short(tmp_path / "a.ply") is None
    (tmp_path / "b.ply").write_text(head + "0 0 0\n1 0 0\n")
    assert ply_cut_short(tmp_path / "b.ply") == "the header declares 3 rows, the file holds 2"
