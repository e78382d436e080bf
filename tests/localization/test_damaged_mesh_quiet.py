"""A damaged PLY mesh is one error line: open3d's reader printed "RPly: Unexpected end of file" (on the real
stderr, from C) and "[Open3D WARNING] Read PLY failed" lines before kinfu's own error."""

from __future__ import annotations

import pytest

from kinfu_cli.core.errors import KinfuError
from kinfu_cli.evaluation.reconstruction import read_mesh_arrays
from kinfu_cli.localization.mesh_model import read_mesh
from kinfu_cli.sim.scenario import _read_mesh

DAMAGED = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n"


@pytest.mark.parametrize("reader", [read_mesh, _read_mesh, read_mesh_arrays])
def test_a_damaged_ply_is_an_error_without_reader_chatter(tmp_path, capfd, reader):
    path = tmp_path / "mesh.ply"
    path.write_bytes(DAMAGED)
    try:
        reader(path)  # read_mesh_arrays keeps the vertices it could read (a reconstruction may be a cloud)
    except KinfuError as err:
        assert str(path) in str(err)
    else:
        assert reader is read_mesh_arrays
    out, err_text = capfd.readouterr()
    assert out == "" and err_text == "", (out, err_text)
