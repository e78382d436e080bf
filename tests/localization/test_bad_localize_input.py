"""Bad `kinfu localize` input found by fuzzing: --beta out of range, points beyond any scene, point sets that
cannot fix a pose (on one point, on a line), and particle / point counts no memory holds."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.localization.mesh_model import MeshModel
from kinfu_cli.localization.refine import pose_std

V = np.array([[0, 0, 0], [0.2, 0, 0], [0.05, 0.12, 0], [0.03, 0.04, 0.09]], dtype=float)
V = V - V.mean(0)
F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]])
FAST = ["--particles", "60", "--quiet", "--prior", "zero"]


@pytest.fixture()
def files(tmp_path):
    mesh = tmp_path / "model.ply"
    o3d.io.write_triangle_mesh(str(mesh), o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V),
                                                                    o3d.utility.Vector3iVector(F)))
    pts = tmp_path / "touches.txt"
    np.savetxt(pts, MeshModel(V, F).sample_surface(20, np.random.default_rng(0)))
    return tmp_path, mesh, pts


@pytest.mark.parametrize("beta", ["nan", "inf", "-3", "1e300"])
def test_beta_out_of_range_is_one_line_error(files, beta):
    _, mesh, pts = files
    line = one_line_error(CliRunner().invoke(cli, ["localize", str(mesh), str(pts), "--beta", beta, *FAST]),
                          "--beta", ">= 0", "<= 1000")
    assert "Warning" not in line


def test_eval_localize_checks_beta_and_counts_before_running():
    run = CliRunner().invoke
    base = ["eval", "localize", "--trials", "1", "--shapes", "box", "--methods", "mupf", "--quiet"]
    one_line_error(run(cli, [*base, "--recognition-trials", "0", "--beta", "nan"]), "--beta")
    one_line_error(run(cli, [*base, "--recognition-points", str(10 ** 13)]), "--recognition-points", "GB",
                   "expected at most")


def test_particles_beyond_memory_is_one_line_error(files):
    _, mesh, pts = files
    line = one_line_error(CliRunner().invoke(cli, ["localize", str(mesh), str(pts), "--particles", str(10 ** 12),
                                                   "--quiet"]), "--particles", "GB", "expected at most")
    most = int(line.split("expected at most ")[1].split()[0])
    assert 0 < most < 10 ** 12


def test_points_beyond_any_scene_name_the_file(files):
    tmp, mesh, pts = files
    huge = tmp / "huge.txt"
    np.savetxt(huge, np.loadtxt(pts) * 1e30)
    one_line_error(CliRunner().invoke(cli, ["localize", str(mesh), str(huge), *FAST]), "huge.txt",
                   "within 1e+06 m")


def _run_json(mesh, path):
    res = CliRunner().invoke(cli, ["localize", str(mesh), str(path), "--json", *FAST])
    assert res.exit_code == 0, res.output
    return json.loads(res.output[res.output.index("{"):])


def test_points_on_one_point_or_a_line_are_ambiguous(files):
    tmp, mesh, _ = files
    same = tmp / "same.txt"
    np.savetxt(same, np.repeat(V[3][None], 20, axis=0))
    doc = _run_json(mesh, same)
    assert doc["status"] == "ambiguous"
    assert any("of one point" in w for w in doc["warnings"]), doc["warnings"]
    line = tmp / "edge.txt"  # along the model's edge 0-1
    np.savetxt(line, V[0] + np.linspace(0.1, 0.9, 30)[:, None] * (V[1] - V[0]))
    doc = _run_json(mesh, line)
    assert doc["status"] == "ambiguous"
    assert any("of a line" in w for w in doc["warnings"]), doc["warnings"]


def test_pose_std_of_a_free_turn_is_large_not_zero():
    model = MeshModel(V, F)
    edge = V[0] + np.linspace(0.1, 0.9, 30)[:, None] * (V[1] - V[0])
    std = pose_std(model, edge, np.zeros(3), np.eye(3), 0.002)
    assert np.all(np.isfinite(std))
    assert std[3:].max() > np.radians(90)  # the turn about the edge: the pseudo-inverse made it 0
    spread = pose_std(model, model.sample_surface(50, np.random.default_rng(1)), np.zeros(3), np.eye(3), 0.002)
    assert spread[:3].max() < 0.01 and spread[3:].max() < np.radians(5)
