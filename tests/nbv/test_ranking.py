"""Viewpoints, ranking on hand-made volumes with a known answer, and the `kinfu nbv` command."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, load_ternary, save_ternary
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.nbv.sensor import camera_from_options
from kinfu_cli.nbv.ranking import (estimate_table_z, forget_around, rank_poi, reject_reasons, score_views,
                                   unknown_in_sphere)
from kinfu_cli.nbv.raycast import RayVolume
from kinfu_cli.core.poses import matrix_to_quaternion
from kinfu_cli.fusion.volume import FORMAT
from kinfu_cli.nbv.viewpoints import SphereSpec, read_candidates, sphere_viewpoints

CAM = CameraModel(60.0, 60.0, 39.5, 29.5, 80, 60, min_range=0.3, max_range=3.0)
# the camera, and a coarse viewing sphere (with --candidates the sphere options are refused: CAMERA alone)
CAMERA = ["--fx", "60", "--fy", "60", "--cx", "39.5", "--cy", "29.5", "--width", "80", "--height", "60", "--quiet"]
SMALL = CAMERA + ["--lon-step", "45", "--lat-step", "30", "--roll-step", "90"]


def test_sphere_viewpoints_look_at_the_poi_from_the_paper_sphere():
    c = np.array([0.3, -0.2, 0.9])
    P = sphere_viewpoints(c)
    assert P.shape == (960, 4, 4)
    R, t = P[:, :3, :3], P[:, :3, 3]
    assert np.allclose(np.einsum("nji,njk->nik", R, R), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(np.linalg.norm(t - c, axis=1), 0.8)
    to_c = (c - t) / 0.8
    assert np.allclose(np.einsum("ni,ni->n", R[:, :, 2], to_c), 1.0)  # optical axis through the POI
    assert np.all(t[:, 2] >= c[2] - 1e-9)  # upper hemisphere
    # roll 0: image y axis points down (upright image) below the pole
    roll0 = np.arange(0, 960, 8)
    below_pole = t[roll0, 2] < c[2] + 0.79
    assert np.all(R[roll0][below_pole][:, 2, 1] < 0)
    assert len(np.unique(np.round(t, 9), axis=0)) == 12 * 9 + 1  # 12 longitudes x 9 latitudes + the pole
    q = matrix_to_quaternion(R[:3])
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)


def test_camera_options_and_widened_fov():
    cam = camera_from_options()
    assert (cam.fx, cam.width, cam.height) == (525.0, 640, 480)
    wide = CameraModel(525.0, 525.0, 319.5, 239.5, 640, 480, vfov_extra_deg=5.0).widened()
    half = lambda c: np.degrees(np.arctan((c.cy + 0.5) / c.fy))  # noqa: E731
    assert half(wide) - half(cam) == pytest.approx(5.0, abs=0.15)
    assert wide.width == 640 and wide.height > 480
    with pytest.raises(ConfigError, match="intrinsics missing: fy, cy"):
        camera_from_options(fx=500.0, cx=320.0)


def box_scene(with_occluder: bool):
    """An unknown box on a table in a 1.6 m cube; optionally a tall occupied wall on its +x side."""
    n, vs = 80, 0.02
    lab = np.full((n, n, n), EMPTY, np.int8)
    lab[:, :, :20] = UNKNOWN  # under the table
    lab[:, :, 20] = OCCUPIED  # table top at z = 0.40..0.42
    lab[36:44, 36:44, 21:29] = UNKNOWN  # the box (0.16 m) at x, y 0.72..0.88, z 0.42..0.58
    if with_occluder:
        lab[50:52, 20:60, 21:50] = OCCUPIED  # wall at x = 1.00..1.04, up to z = 1.0
    return TernaryGrid(lab, np.zeros(3), vs), np.array([0.8, 0.8, 0.5])


def test_unknown_box_is_best_seen_from_where_it_shows_most_and_the_wall_hides_it():
    g, poi = box_scene(with_occluder=False)
    P = sphere_viewpoints(poi, 0.8, lon_step=90, lat_step=30, roll_step=90)
    free = score_views(g, P, CAM, poi, 0.2)
    g2, _ = box_scene(with_occluder=True)
    occl = score_views(g2, P, CAM, poi, 0.2)
    lon = np.degrees(np.arctan2(P[:, 1, 3] - poi[1], P[:, 0, 3] - poi[0])).round() % 360
    lat = np.degrees(np.arcsin(np.clip((P[:, 2, 3] - poi[2]) / 0.8, -1, 1))).round()
    assert free.gain.min() > 0  # an unknown box in free space is seen from everywhere
    # without the wall, the four longitudes at one latitude see the box alike (the scene is symmetric)
    for la in (0, 30, 60):
        sel = (lat == la)
        assert np.ptp(free.gain[sel]) <= 0.02 * free.gain[sel].max()
    # the wall hides the box from the +x side at low latitudes, not from -x
    hidden = (lon == 0) & (lat == 0)
    assert np.all(occl.gain[hidden] == 0) and np.all(occl.counts[hidden, 1] > 0)
    opposite = (lon == 180) & (lat == 0)
    assert np.allclose(occl.gain[opposite], free.gain[opposite])
    best = occl.order()[0]
    assert lon[best] != 0
    assert occl.gain[best] == occl.gain.max()


def test_rejections_below_table_and_inside_occupied_or_unknown():
    g, poi = box_scene(with_occluder=True)
    vol = RayVolume.from_grid(g)
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, :3, 3] = [[0.2, 0.2, 0.3], [1.01, 0.8, 0.8], [0.8, 0.8, 0.5], [0.3, 0.3, 1.2]]
    assert estimate_table_z(g) == pytest.approx(0.42)
    reasons = reject_reasons(vol, T, table_z=estimate_table_z(g))
    assert reasons == ["below_table", "inside_occupied", "inside_unknown", None]
    r = rank_poi(g, poi, CAM, candidates=T, table_z=0.42)
    assert r.scores.rejected() == {"below_table": 1, "inside_occupied": 1, "inside_unknown": 1}
    assert list(r.scores.order()) == [3]


def test_forget_around_and_inc_th_say_when_a_poi_is_reconstructed():
    g, poi = box_scene(with_occluder=False)
    g.labels[36:44, 36:44, 21:29] = OCCUPIED  # the box is fully known now
    r = rank_poi(g, poi, CAM, sphere=SphereSpec(lon_step=90, lat_step=45, roll_step=180))
    assert r.best_gain == 0 and r.reconstructed
    n = forget_around(g, poi, 0.2)
    assert n > 0 and unknown_in_sphere(g, poi, 0.2) == pytest.approx(4 / 3 * np.pi * 10 ** 3, rel=0.1)
    r = rank_poi(g, poi, CAM, sphere=SphereSpec(lon_step=90, lat_step=45, roll_step=180))
    assert not r.reconstructed and r.best_gain > r.inc_th > 0
    r = rank_poi(g, poi, CAM, sphere=SphereSpec(lon_step=90, lat_step=45, roll_step=180), inc_th=1e9)
    assert r.reconstructed


@pytest.fixture
def scene_files(tmp_path):
    g, poi = box_scene(with_occluder=True)
    vol = tmp_path / "ternary.npz"
    save_ternary(vol, g)
    pois = tmp_path / "pois.json"
    pois.write_text(json.dumps({"pois": [{"id": 3, "position": poi.tolist(), "radius": 0.2}]}))
    return vol, pois, tmp_path


def test_cli_ranks_views_and_writes_views_json_and_plot(scene_files):
    vol, pois, tmp = scene_files
    out, png = tmp / "views.json", tmp / "views.png"
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--clear", "--top", "5", "-o", str(out),
                                   "--plot", str(png), "--exact-rolls"] + SMALL)
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    p = doc["pois"][0]
    assert p["id"] == 3 and p["candidates"] == 8 * 4 * 4 and len(p["views"]) == 5
    gains = [v["gain"] for v in p["views"]]
    assert gains == sorted(gains, reverse=True) and gains[0] > 0
    v = p["views"][0]
    for key in ("pose", "position", "quaternion", "gain", "rays_unknown", "rays_occupied", "rays_empty_exit"):
        assert key in v
    T = np.array(v["pose"])
    assert np.allclose(T[:3, 3], v["position"]) and len(v["quaternion"]) == 4
    assert p["cleared_voxels"] > 0 and p["reconstructed"] is False
    assert png.stat().st_size > 10_000
    # --json on stdout gives the same gains for the same poses given as a candidates file
    cand = tmp / "cand.json"
    cand.write_text(json.dumps([pv["pose"] for pv in p["views"][:3]]))
    assert read_candidates(cand).shape == (3, 4, 4)
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--clear", "--json",
                                   "--candidates", str(cand), "--exact-rolls"] + CAMERA)
    assert res.exit_code == 0, res.output
    doc2 = json.loads(res.output)
    assert [w["gain"] for w in doc2["pois"][0]["views"]] == pytest.approx(gains[:3])


@pytest.mark.parametrize("case", ["no_pois", "poi_outside", "other_version", "intrinsics", "bad_candidates"])
def test_cli_bad_input_is_a_one_line_error(scene_files, case):
    vol, pois, tmp = scene_files
    out = tmp / "views.json"
    args = ["nbv", str(vol), "--pois", str(pois), "-o", str(out)] + SMALL
    if case == "no_pois":
        pois.write_text(json.dumps({"pois": []}))
        expect = "no POIs"
    elif case == "poi_outside":
        pois.write_text(json.dumps({"pois": [{"id": 0, "position": [5.0, 0.8, 0.5]}]}))
        expect = "POI 0 at (5.000, 0.800, 0.500) is outside the volume"
    elif case == "other_version":
        np.savez(vol, meta=np.array(json.dumps({"format": FORMAT, "format_version": 99})))
        expect = "version 99"
    elif case == "intrinsics":
        args = ["nbv", str(vol), "--pois", str(pois), "-o", str(out), "--fx", "500", "--quiet"]
        expect = "intrinsics missing"
    else:
        (tmp / "c.json").write_text(json.dumps([[[1, 0], [0, 1]]]))
        args = ["nbv", str(vol), "--pois", str(pois), "-o", str(out), "--candidates", str(tmp / "c.json")] + CAMERA
        expect = "expected a list of 4x4 poses"
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: error:") and expect in lines[0], res.output
    assert not out.exists()


def test_cli_camera_info_without_camera_info_topic_is_an_error(shared_data, tmp_path, scene_files):
    bag = shared_data("ros-recordings", "tf_example.bag")
    vol, pois, _ = scene_files
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--camera-info", str(bag), "--quiet"])
    assert res.exit_code == 2
    assert "kinfu: error:" in res.output and "CameraInfo" in res.output and "tf_example.bag" in res.output


def test_cli_intrinsics_from_the_recordings_camera_info(scene_files, sample_dir):
    vol, pois, _ = scene_files
    args = ["nbv", str(vol), "--pois", str(pois), "--json", "--lon-step", "90", "--lat-step", "45",
            "--roll-step", "180", "--quiet", "--vfov-extra", "0"]
    res = CliRunner().invoke(cli, args + ["--camera-info", str(sample_dir / "recording.mcap")])
    assert res.exit_code == 0, res.output
    cam = json.loads(res.output)["camera"]
    assert (cam["fx"], cam["cx"], cam["width"], cam["height"]) == (292.5, 159.5, 320, 240)


def test_cli_objects_mode_plans_views_at_the_contours_of_a_salient_segment(tmp_path):
    from kinfu_cli.sim.scene import primitive_tabletop_scene
    from kinfu_cli.sim.tsdf import scene_tsdf

    origin, vs, shape = np.array([-0.7, -0.5, 0.6]), 0.01, (140, 100, 45)
    scene = primitive_tabletop_scene(3, n_objects=3, stacked=False)
    tsdf, w = scene_tsdf(scene, origin, vs, shape, box_min=(-0.7, -0.5, 0.6), box_max=(0.7, 0.5, 1.05))
    labels = np.where(w == 0, 0, np.where(tsdf <= 0, 1, -1)).astype(np.int8)
    c = origin + (np.indices(shape).transpose(1, 2, 3, 0) + 0.5) * vs
    for p in scene.objects:  # the back of every object unseen
        back = (c[..., 1] > p.center[1]) & (np.hypot(c[..., 0] - p.center[0], c[..., 1] - p.center[1])
                                            < np.hypot(p.size[0] / 2, p.size[1] / 2) + 0.06) & (c[..., 2] > 0.7)
        labels[back] = 0
    vol = tmp_path / "ternary.npz"
    save_ternary(vol, TernaryGrid(labels, origin, vs))
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--mode", "objects", "--json", "--top", "3", "--fx", "120",
                                   "--fy", "120", "--cx", "79.5", "--cy", "59.5", "--width", "160", "--height", "120",
                                   "--min-range", "0.3", "--quiet"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["mode"] == "objects" and doc["pose"] is not None and doc["score"] > 0
    assert doc["candidates_evaluated"] < doc["candidates_total"]
    gains = [v["gain"] for v in doc["views"]]
    assert len(gains) == 3 and gains == sorted(gains, reverse=True) and len(doc["views"][0]["quaternion"]) == 4
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--quiet"])
    assert res.exit_code == 2 and "--pois: required" in res.output


def test_table_height_is_the_highest_large_upward_surface_not_the_floor():
    g, _ = box_scene(with_occluder=False)
    g.labels[:, :, 5] = OCCUPIED  # a floor at z = 0.10..0.12, larger than the table below
    g.labels[:, :, 6:20] = EMPTY
    g.labels[:40, :, 20] = EMPTY  # the table covers only half of the floor
    assert estimate_table_z(g) == pytest.approx(0.42)


def test_cli_warns_when_pois_and_volume_frames_differ(scene_files):
    vol, pois, tmp = scene_files
    g = load_ternary(vol)
    g.frame = "world"
    save_ternary(vol, g)
    assert load_ternary(vol).frame == "world"
    doc = json.loads(pois.read_text())
    for frame, warned in (("world", False), ("polhemus_base", True), ("", False)):
        doc["frame"] = frame
        pois.write_text(json.dumps(doc))
        res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--json"] + SMALL)
        assert res.exit_code == 0, res.output
        out = json.loads(res.stdout)
        assert bool(out["warnings"]) == warned
        assert ("kinfu: warning: --pois" in res.stderr) == warned
