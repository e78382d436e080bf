"""`kinfu eval fusion`: reconstruction error and the paper's object measures (Table 1) on the sample recording.

The sample's initial scan (24 frames, TF = robot kinematics poses) is fused in-process on a coarse grid (1.6 m cube,
256^3, 6.25 mm voxels) once per module; perturbed copies of that mesh check that the measures see what was done.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation.object_measures import (fit_table_plane, footprint_axes, ground_truth_objects,
                                                   object_measures)
from kinfu_cli.evaluation.reconstruction import (Reconstruction, fused_window, load_reconstruction, mesh_scene,
                                                 observed_surface, score_reconstruction, state_frames, visible_mask,
                                                 visible_mask_exact)
from kinfu_cli.evaluation.tables import format_fusion_tables
from kinfu_cli.sim.sampling import sample_surface
from kinfu_cli.sim.scenario import load_ground_truth

VOXEL = 1.6 / 256
SPACING = 0.01  # coarser true-surface sampling than the CLI default: keeps the tests fast


@pytest.fixture(scope="module")
def gt(sample_dir):
    return load_ground_truth(sample_dir / "ground_truth")


@pytest.fixture(scope="module")
def fused_dir(sample_dir, gt, tmp_path_factory):
    """`kinfu fuse`-like output folder (mesh.ply + volume.npz) of the initial scan, forced (TF) poses."""
    import open3d as o3d

    from kinfu_cli.fusion.volume import TernaryVolume
    from kinfu_cli.io.frames import iter_frames
    from kinfu_cli.io.recording import open_recording

    n_scan = gt.info["frames"]["scan"]
    table = gt.info["table"]
    origin = [table["center"][0] - 0.8, table["center"][1] - 0.8, table["top_z"] - 0.8]
    vol = TernaryVolume(size=1.6, resolution=256, origin=origin)
    with open_recording(sample_dir / "recording.mcap") as rec:
        for i, f in enumerate(iter_frames(rec)):
            if i >= n_scan:
                break
            vol.integrate(f.depth, f.K, f.T_world_camera, f.color)
    out = tmp_path_factory.mktemp("fused_scan")
    vol.save(out / "volume.npz")
    assert o3d.io.write_triangle_mesh(str(out / "mesh.ply"), vol.extract_mesh())
    return out


@pytest.fixture(scope="module")
def rec(fused_dir):
    return load_reconstruction(fused_dir)


@pytest.fixture(scope="module")
def surface(rec, gt):
    return observed_surface(gt, "before", rec.volume.bounds(), spacing=SPACING)


@pytest.fixture(scope="module")
def score(rec, gt, surface):
    return score_reconstruction(rec, gt, "before", surface=surface)


def _vertex_normals(rec: Reconstruction) -> np.ndarray:
    """The normals stored in the fused mesh.ply (they point into empty space, i.e. out of the objects)."""
    import open3d as o3d

    m = o3d.io.read_triangle_mesh(str(rec.source))
    assert m.has_vertex_normals() and len(m.vertex_normals) == len(rec.vertices)
    return np.asarray(m.vertex_normals)


def test_forced_pose_scan_is_within_one_voxel_and_nearly_complete(score):
    # measured on the sample: mean 1.6 mm, median 0.5 mm, 98 % of vertices and ~95 % of the seen surface within 1 cm
    assert score.accuracy.mean <= VOXEL
    assert score.accuracy.median <= 0.5 * VOXEL
    assert score.precision >= 0.95
    assert score.completeness >= 0.90
    assert score.completeness_distances.median <= VOXEL
    assert score.vertices_outside_region == 0
    assert score.samples_observed > 10_000


def test_volume_counts_and_observed_share(score, rec):
    cov = score.coverage
    assert cov is not None
    assert sum(cov["counts"].values()) == int(np.prod(rec.volume.shape))
    assert cov["counts"] == rec.volume.counts()
    # the surface the cameras saw is mostly known; much of the true surface in the grid never was (underside of
    # the table, floor under it, back sides of the objects)
    assert cov["visible_surface_known_share"] >= 0.85
    assert cov["surface_in_grid_known_share"] < cov["visible_surface_known_share"]


def test_object_measures_of_forced_pose_scan(rec, gt):
    res = object_measures(rec.vertices, gt, "before")
    rows = {r["id"]: r for r in res.objects}
    assert set(rows) == {o["id"] for o in gt.objects if o["present_before"]}
    assert all(r["error"] is not None for r in rows.values())
    # heights within 1 cm for every object (measured: 0-9 mm; the cone's tip is rounded off by the TSDF)
    for r in rows.values():
        assert abs(r["error"]["height"]) <= 0.01, r
    # the table plane is found where it is
    assert abs(res.plane[3] - res.plane_truth[3]) < 0.003
    assert res.plane[:3] @ res.plane_truth[:3] > np.cos(np.radians(1.0))
    # Table 1 statistic (pooled height / major / minor, mean abs. error): measured 9 mm (st. dev. 12 mm). The
    # footprints of the box and cylinder come out 1-2 cm too large: their -y sides face away from the scan arc
    # (+y side), the few grazing views of them are outvoted by the many views whose 3 cm truncation band reaches
    # past the top edges, which leaves a skirt there (half as wide with 1.5 cm truncation); the cone's far base is
    # unseen (minor axis 2 cm short); the sphere's footprint is within 5 mm.
    assert res.mean_abs <= 0.0125
    assert abs(rows["obj3"]["error"]["major"]) <= 0.005 and abs(rows["obj3"]["error"]["minor"]) <= 0.005
    assert res.to_json()["paper_table_1"][1]["tracking"] == "robot kinematics"


def test_objects_only_mesh_falls_back_to_the_true_table_plane(rec, gt):
    above = rec.vertices[rec.vertices[:, 2] > gt.info["table"]["top_z"] + 0.01]
    res = object_measures(above, gt, "before")
    assert res.settings["table_plane"].startswith("true")
    assert np.allclose(res.plane, res.plane_truth)
    assert all(abs(r["error"]["height"]) <= 0.01 for r in res.objects)


def test_mesh_offset_2cm_along_normals_gives_2cm_error(rec, gt, surface, score):
    moved = Reconstruction(rec.vertices + 0.02 * _vertex_normals(rec), rec.triangles, rec.source)
    s = score_reconstruction(moved, gt, "before", surface=surface)
    assert 0.017 <= s.accuracy.median <= 0.023
    assert 0.014 <= s.accuracy.mean <= 0.023
    assert s.precision < 0.2 < score.precision
    assert s.completeness < 0.5 * score.completeness


def test_mesh_raised_2cm_moves_table_but_not_object_heights(rec, gt, surface):
    raised = Reconstruction(rec.vertices + [0.0, 0.0, 0.02], rec.triangles, rec.source)
    s = score_reconstruction(raised, gt, "before", surface=surface)
    # most of the seen surface is horizontal (table top, floor, object tops): median error = the shift
    assert 0.018 <= s.accuracy.median <= 0.022
    base = object_measures(rec.vertices, gt, "before")
    up = object_measures(raised.vertices, gt, "before")
    assert abs((up.plane[3] - base.plane[3]) + 0.02) < 1e-3  # plane z = -d rose by 2 cm
    for a, b in zip(base.objects, up.objects):
        assert abs(a["measured"]["height"] - b["measured"]["height"]) < 1e-3
        assert abs(a["measured"]["major"] - b["measured"]["major"]) < 1e-3


def test_true_mesh_scores_perfectly(gt, surface):
    m = gt.mesh("before")
    truth = Reconstruction(np.asarray(m.vertices), np.asarray(m.triangles), gt.folder / "scene_before.ply")
    s = score_reconstruction(truth, gt, "before", surface=surface)
    assert s.accuracy.max < 1e-4
    assert s.completeness == 1.0 and s.precision == 1.0


def test_after_state_shows_the_unfused_move(rec, gt):
    # the scan never saw the cone at its new place: in the after state it has no reconstructed points there
    res = object_measures(rec.vertices, gt, "after")
    rows = {r["id"]: r for r in res.objects}
    moved = [o["id"] for o in gt.objects if "center_before" in o]
    assert moved
    for i in moved:  # absent there: too few points to measure, or only a low skirt of table noise
        r = rows[i]
        assert r["error"] is None or r["measured"]["height"] < 0.5 * r["true"]["height"], r
    assert all(rows[i]["error"] is not None for i in rows if i not in moved)
    assert all(abs(rows[i]["error"]["height"]) <= 0.01 for i in rows if i not in moved)


def test_footprint_axes_of_a_rotated_rectangle():
    rng = np.random.default_rng(3)
    xy = rng.uniform([-0.075, -0.02], [0.075, 0.02], size=(4000, 2))
    xy = np.vstack([xy, [[-0.075, -0.02], [0.075, 0.02], [-0.075, 0.02], [0.075, -0.02]]])
    c, s = np.cos(0.7), np.sin(0.7)
    xy = xy @ np.array([[c, s], [-s, c]]) + [0.3, -0.1]
    major, minor = footprint_axes(xy, "rect")
    assert abs(major - 0.15) < 1e-4 and abs(minor - 0.04) < 1e-4
    major, minor = footprint_axes(xy, "pca")
    assert abs(major - 0.15) < 2e-3 and abs(minor - 0.04) < 2e-3


def test_cli_json_and_results_file(fused_dir, gt, tmp_path, score):
    import open3d as o3d

    out = tmp_path / "res.json"
    err_mesh = tmp_path / "error.ply"
    res = CliRunner().invoke(cli, ["eval", "fusion", str(fused_dir), "--ground-truth", str(gt.folder), "--state",
                                   "before", "--spacing", str(SPACING), "--json", "-o", str(out), "--quiet",
                                   "--error-mesh", str(err_mesh)])
    assert res.exit_code == 0, res.output
    em = o3d.io.read_triangle_mesh(str(err_mesh))
    cols = np.asarray(em.vertex_colors)
    assert len(cols) == score.vertices_total
    d = score.vertex_distances
    # 'turbo': red channel high for large errors, low (dark blue) for small ones
    assert cols[d > 0.015, 0].mean() > 0.5 > cols[d < 0.001, 0].mean()
    doc = json.loads(res.stdout)
    assert json.loads(out.read_text())["objects"] == doc["objects"]
    assert doc["input"]["state"] == "before"
    assert doc["reconstruction"]["accuracy"]["mean"] <= VOXEL
    assert doc["reconstruction"]["volume"]["counts"]["unknown"] > 0
    assert doc["table_1"][-1]["scenario"] == "this run"
    assert doc["table_1"][-1]["mean_abs"] == pytest.approx(doc["objects"]["mean_abs"])
    assert doc["table_1"][-1]["objects_measured"] == doc["table_1"][-1]["objects_total"] == 4
    # each object was seen from the scan arc, none all around except the box (measured: 100 / 82 / 71 / 90 %)
    shares = [o["surface_seen_share"] for o in doc["objects"]["objects"]]
    assert all(0.5 < s <= 1.0 for s in shares) and min(shares) < 0.9
    text = format_fusion_tables(doc)
    assert "robot kinematics" in text and "this run" in text and "completeness" in text


def _empty_ply(path):
    path.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 0\nproperty list uchar int vertex_indices\nend_header\n")
    return path


@pytest.mark.parametrize("case", ["missing", "dir-without-mesh", "zero-bytes", "no-vertices", "gt-without-changes",
                                  "bad-threshold"])
def test_bad_input_is_one_line_exit_2(case, gt, fused_dir, tmp_path):
    mesh = fused_dir
    gt_dir = gt.folder
    extra = []
    if case == "missing":
        mesh, expect = tmp_path / "nope" / "mesh.ply", "no such mesh file"
    elif case == "dir-without-mesh":
        (tmp_path / "fuse_out").mkdir()
        mesh, expect = tmp_path / "fuse_out", "no mesh.ply"
    elif case == "zero-bytes":
        mesh = tmp_path / "mesh.ply"
        mesh.write_bytes(b"")
        expect = "no vertices"
    elif case == "no-vertices":
        mesh, expect = _empty_ply(tmp_path / "mesh.ply"), "no vertices"
    elif case == "gt-without-changes":
        gt_dir = tmp_path / "gt"
        gt_dir.mkdir()
        expect = "no changes.json"
    else:
        extra, expect = ["--threshold", "0"], "--threshold"
    out = tmp_path / "res.json"
    res = CliRunner().invoke(cli, ["eval", "fusion", str(mesh), "--ground-truth", str(gt_dir), "-o", str(out),
                                   "--quiet", "--spacing", "0.05", *extra])
    assert res.exit_code == 2, res.output
    err = [ln for ln in res.stderr.splitlines() if ln.startswith("kinfu: error:")]
    assert len(err) == 1 and expect in err[0], res.stderr
    assert "Traceback" not in res.output
    assert not out.exists()
    assert not list(tmp_path.glob(".res.*"))


def test_zbuffer_visibility_agrees_with_exact_occlusion_rays(gt):
    """visible_mask (one rendered depth image per pose) vs casting a ray from the camera to every sample."""
    m = gt.mesh("before")
    v, f = np.asarray(m.vertices), np.asarray(m.triangles)
    scene = mesh_scene(v, f)
    pts, nrm = sample_surface(v, f, spacing=0.01, seed=1)
    keep = np.all(np.abs(pts[:, :2]) < 1.0, axis=1)  # the table and the floor around it
    pts, nrm = pts[keep], nrm[keep]
    poses = gt.poses[:24:3]
    approx = visible_mask(pts, nrm, scene, poses, gt.K, gt.width, gt.height)
    exact = visible_mask_exact(pts, nrm, scene, poses, gt.K, gt.width, gt.height)
    assert exact.sum() > 5000
    agree = np.mean(approx == exact)
    assert agree >= 0.995, agree  # measured 0.999
    assert np.mean(approx[exact]) >= 0.99  # what is truly visible is found (measured 0.997)
    assert np.mean(exact[approx]) >= 0.99  # and little else (measured 0.996)


def test_fused_time_window_selects_the_true_poses(gt):
    n_scan = gt.info["frames"]["scan"]
    assert len(state_frames(gt, "before")) == n_scan
    assert len(state_frames(gt, "after")) == len(gt.poses)
    # the scan ends at 0.5 + 23 / 5 = 5.1 s, the after views start after the hand left (> 11 s)
    assert list(state_frames(gt, "after", (None, 5.5))) == list(range(n_scan))
    assert list(state_frames(gt, "after", (6.0, None))) == list(range(n_scan, len(gt.poses)))
    assert len(state_frames(gt, "before", (6.0, None))) == 0
    assert fused_window({"frames": {"start_s": None, "end_s": 5.5}}) == (None, 5.5)
    assert fused_window({"frames": {"start_s": None, "end_s": None}}) is None


def test_window_without_poses_of_the_state_is_refused(fused_dir, gt, tmp_path):
    import shutil

    out_dir = tmp_path / "fuse_late"
    out_dir.mkdir()
    shutil.copy(fused_dir / "mesh.ply", out_dir / "mesh.ply")
    (out_dir / "report.json").write_text(json.dumps({"pose_mode": "forced", "frames": {"start_s": 6.0,
                                                                                        "end_s": None}}))
    res = CliRunner().invoke(cli, ["eval", "fusion", str(out_dir), "--ground-truth", str(gt.folder), "--state",
                                   "before", "-o", str(tmp_path / "r.json"), "--quiet"])
    assert res.exit_code == 2
    assert "holds no ground-truth camera pose" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "r.json").exists()


def test_object_truth_without_its_mesh_is_cut_from_the_scene(gt, tmp_path):
    """A removed object has no objects/<id>.ply: its truth comes from the scene mesh inside its box; for the
    moved cone both ways must give the same measures."""
    import shutil

    from kinfu_cli.evaluation.object_measures import ground_truth_objects, measure, table_plane_truth

    copy = tmp_path / "gt"
    shutil.copytree(gt.folder, copy)
    moved = next(o["id"] for o in gt.objects if "center_before" in o)
    (copy / "objects" / f"{moved}.ply").unlink()
    plane = table_plane_truth(gt)
    a = {o.id: measure(o.vertices, plane) for o in ground_truth_objects(gt, "before")}
    b = {o.id: measure(o.vertices, plane) for o in ground_truth_objects(load_ground_truth(copy), "before")}
    assert a.keys() == b.keys()
    for key in ("height", "major", "minor"):
        assert abs(a[moved][key] - b[moved][key]) < 1e-6
    size = np.array(next(o["size"] for o in gt.objects if o["id"] == moved))
    assert abs(a[moved]["height"] - size[2]) < 1e-6


def test_table_plane_fit_gives_one_answer_per_seed(rec, gt):
    """open3d's parallel RANSAC stops early: on several threads the seeded plane depended on thread timing.
    The fit runs on one thread, and open3d's thread limit is restored afterwards."""
    import open3d as o3d

    objects = ground_truth_objects(gt, "before")
    threads = o3d.utility.get_max_threads()
    planes = [fit_table_plane(rec.vertices, gt, objects) for _ in range(5)]
    assert all(np.array_equal(planes[0], p) for p in planes[1:])
    assert o3d.utility.get_max_threads() == threads
