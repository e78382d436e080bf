"""`kinfu localize` / `kinfu eval localize`: the pose.json contract, points from a text file, a PLY and a
kinfu segment output, and one-line errors for bad input."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest
from click.testing import CliRunner
from conftest import one_line_error
from scipy.spatial.transform import Rotation

from kinfu_cli.cli import cli
from kinfu_cli.localization.points import read_segment_points
from kinfu_cli.segmentation.outputs import segment_colors

V = np.array([[0, 0, 0], [0.2, 0, 0], [0.05, 0.12, 0], [0.03, 0.04, 0.09]], dtype=float)
F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]])
FAST = ["--particles", "60", "--quiet", "--prior", "zero"]


def _write_mesh(path, v=V, f=F):
    o3d.io.write_triangle_mesh(str(path), o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v - v.mean(0)),
                                                                    o3d.utility.Vector3iVector(f)))
    return path


def _points(n=20, seed=0):
    from kinfu_cli.localization.mesh_model import MeshModel

    m = MeshModel(V - V.mean(0), F)
    rng = np.random.default_rng(seed)
    R = Rotation.from_euler("z", 10, degrees=True).as_matrix()
    return m.sample_surface(n, rng) @ R.T + [0.01, 0, 0]


@pytest.fixture()
def files(tmp_path):
    mesh = _write_mesh(tmp_path / "model.ply")
    txt = tmp_path / "touches.txt"
    np.savetxt(txt, _points(), header="x y z contact points in measurement order")
    return tmp_path, mesh, txt


def test_pose_json_contract(files):
    tmp, mesh, txt = files
    out = tmp / "pose.json"
    res = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "-o", str(out), *FAST, "--max-index", "1"])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    for key in ("model", "status", "index_m", "max_index_m", "seconds", "window", "pose", "points", "parameters",
                "warnings", "input", "prior_mean"):
        assert key in doc
    assert doc["status"] == "converged" and doc["points"] == 20 and doc["window"] == 10
    T = np.array(doc["pose"]["matrix"])
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9) and np.allclose(T[3], [0, 0, 0, 1])
    assert np.allclose(T[:3, 3], doc["pose"]["position"])
    q = doc["pose"]["quaternion_xyzw"]
    assert np.allclose(Rotation.from_quat(q).as_matrix(), T[:3, :3], atol=1e-9)
    assert doc["index_m"] < 0.05


def test_not_converged_is_reported_without_a_pose(files):
    tmp, mesh, txt = files
    res = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "--json", *FAST, "--max-index", "1e-9"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output[res.output.index("{"):])
    assert doc["status"] == "not_converged" and doc["pose"] is None
    assert any("did not converge" in w for w in doc["warnings"])


def test_recognition_json_lists_every_model(files):
    tmp, mesh, txt = files
    other = _write_mesh(tmp / "other.ply", v=V * [1, 1, 1.6])
    res = CliRunner().invoke(cli, ["localize", "--models", f"{mesh},{other}", str(txt), "--json", *FAST])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output[res.output.index("{"):])
    rec = doc["recognition"]
    assert [m["model"] for m in rec["models"]] == ["model", "other"]
    best = min(rec["models"], key=lambda m: m["index_m"])
    assert rec["chosen"] == best["model"] == doc["model"]


def _segment_output(tmp, pts_by_id):
    pts = np.concatenate(list(pts_by_id.values()))
    labels = np.concatenate([np.full(len(p), k) for k, p in pts_by_id.items()])
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pc.colors = o3d.utility.Vector3dVector(segment_colors(labels))
    o3d.io.write_point_cloud(str(tmp / "segments.ply"), pc)
    segs = [{"id": int(k), "kind": "object", "point_count": len(p)} for k, p in pts_by_id.items() if k > 0]
    (tmp / "segments.json").write_text(json.dumps({"segments": segs}))
    return tmp / "segments.json"


def test_segment_points_are_read_by_colour(tmp_path):
    rng = np.random.default_rng(0)
    parts = {1: rng.random((30, 3)), 3: _points(25), 4: rng.random((12, 3))}
    meta = _segment_output(tmp_path, parts)
    got = read_segment_points(meta, 3)
    assert got.shape == (25, 3) and np.allclose(np.sort(got, axis=0), np.sort(parts[3], axis=0), atol=1e-6)


def test_bad_inputs_are_one_line_errors(files):
    tmp, mesh, txt = files
    run = CliRunner().invoke
    open_mesh = _write_mesh(tmp / "open.ply", f=F[:3])
    one_line_error(run(cli, ["localize", str(open_mesh), str(txt), *FAST]), "open.ply", "not watertight")
    empty = tmp / "empty.ply"
    empty.write_text("ply\nformat ascii 1.0\nelement vertex 0\nelement face 0\nproperty list uchar int "
                     "vertex_indices\nend_header\n")
    one_line_error(run(cli, ["localize", str(empty), str(txt), *FAST]), "empty.ply", "empty mesh")
    two = tmp / "two.txt"
    np.savetxt(two, _points(2))
    one_line_error(run(cli, ["localize", str(mesh), str(two), *FAST]), "2 points", "at least 3")
    bad = tmp / "bad.txt"
    bad.write_text("1 2\n3 4\n")
    one_line_error(run(cli, ["localize", str(mesh), str(bad), *FAST]), "bad.txt", "three numbers")
    meta = _segment_output(tmp, {1: _points(20)})
    one_line_error(run(cli, ["localize", str(mesh), "--segments", str(meta), "--segment", "7", *FAST]),
                   "--segment", "no object segment with id 7")
    one_line_error(run(cli, ["localize", str(mesh), str(txt), "--particles", "0", *FAST[2:]]), "--particles")
    one_line_error(run(cli, ["localize", str(mesh), str(txt), "--window", "50", *FAST]), "--window", "exceeds")
    one_line_error(run(cli, ["localize", str(mesh), str(txt), "--prior", "1,2", *FAST[:3]]), "--prior")


def test_segment_input_localises(files):
    tmp, mesh, _ = files
    meta = _segment_output(tmp, {2: _points(20, seed=4)})
    res = CliRunner().invoke(cli, ["localize", str(mesh), "--segments", str(meta), "--segment", "2", "--json",
                                   *FAST[:3]])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output[res.output.index("{"):])
    assert doc["points"] == 20 and "segment 2" in doc["input"]["points"]


@pytest.mark.slow
def test_eval_localize_small_run(tmp_path):
    """Two trials on the tetrahedron with every method: the JSON holds per-method summaries beside the
    thesis' numbers, and successes never exceed trials."""
    out = tmp_path / "ev.json"
    res = CliRunner().invoke(cli, ["eval", "localize", "--shapes", "tetrahedron", "--trials", "2", "--particles",
                                   "60", "--recognition-trials", "0", "--quiet", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "Open3D" not in res.output
    doc = json.loads(out.read_text())
    per = doc["shapes"]["tetrahedron"]
    assert set(per) == {"mupf", "scaling_series", "ransac_icp"}
    for block in per.values():
        s = block["summary"]
        assert s["trials"] == 2 and 0 <= s["successes"] <= 2 and s["mean_index_m"] >= 0
    assert doc["thesis"]["mupf"]["tetrahedron"][4] == 50
    one_line_error(CliRunner().invoke(cli, ["eval", "localize", "--shapes", "sphere"]), "--shapes")


def test_many_points_are_thinned_in_order_and_said(files):
    """A fused segment gives thousands of points and the filter takes one at a time: more than --max-points
    (default 100, the thesis' cloud size) are thinned, kept in their measurement order, with a warning."""
    tmp, mesh, _ = files
    pts = _points(n=400, seed=1)
    txt = tmp / "many.txt"
    np.savetxt(txt, pts)
    out = tmp / "pose.json"
    res = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "-o", str(out), *FAST, "--max-index", "1",
                                   "--max-points", "30"])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["points"] == 30 and doc["window"] == 15
    assert any("used 30 of the 400 points" in w for w in doc["warnings"])
    res = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "-o", str(out), *FAST, "--max-points", "-1"])
    assert res.exit_code == 2 and "--max-points" in res.output


def test_quiet_prints_no_summary(files):
    """--quiet printed the pose summary all the same: like fuse, segment, poi and the eval commands, it prints only
    warnings and errors now (the file is still written; --json still prints the JSON)."""
    tmp, mesh, txt = files
    fast = [a for a in FAST if a != "--quiet"]
    loud = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "-o", str(tmp / "a.json"), *fast])
    quiet = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "-o", str(tmp / "b.json"), *fast, "--quiet"])
    assert loud.exit_code == quiet.exit_code == 0, loud.output + quiet.output
    assert loud.stdout.strip() and quiet.stdout == ""
    assert json.loads((tmp / "b.json").read_text())["status"] == "converged"
