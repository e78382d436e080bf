"""`kinfu eval nbv --pois-from` is refused where it would be recorded but not used: a bare mesh SCENE (no hand
trajectory nor true changes: its POI is the given position) and the POI-free exploration."""

from __future__ import annotations

import open3d as o3d
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.nbv_loop import LoopConfig, _cfg_doc, load_scene


def _box(tmp_path):
    path = tmp_path / "box.ply"
    o3d.io.write_triangle_mesh(str(path), o3d.geometry.TriangleMesh.create_box(0.3, 0.3, 0.3))
    return path


@pytest.mark.parametrize("source", ["truth", "gmm-as"])
def test_pois_from_given_with_a_bare_mesh_is_refused(tmp_path, source):
    mesh = _box(tmp_path)
    res = CliRunner().invoke(cli, ["eval", "nbv", str(mesh), "--poi", "0.1", "0.1", "0.1", "--pois-from", source,
                                   "--strategy", "fixed", "--views", "1", "--quiet", "-o", str(tmp_path / "e.json")])
    one_line_error(res, "--pois-from", str(mesh), "bare mesh", "give the POI position")
    assert not (tmp_path / "e.json").exists()


def test_a_bare_mesh_without_pois_from_loads_and_records_the_given_position(tmp_path):
    cfg = LoopConfig(strategies=("fixed",), poi=(0.1, 0.1, 0.1))
    sc = load_scene(_box(tmp_path), cfg)
    assert sc.changes.tolist() == [[0.1, 0.1, 0.1]]
    assert _cfg_doc(cfg)["pois_from"] == "poi"
    assert _cfg_doc(LoopConfig())["pois_from"] == "gmm-as"
    assert _cfg_doc(LoopConfig(pois_from="truth"))["pois_from"] == "truth"


def test_pois_from_with_the_poi_free_exploration_is_refused():
    with pytest.raises(ConfigError) as err:
        LoopConfig(strategies=("objects", "standard"), pois_from="truth").check()
    assert err.value.parameter == "pois_from" and "POI-free exploration (objects,standard)" in str(err.value)
