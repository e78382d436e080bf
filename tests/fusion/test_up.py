"""The world's up direction: decided once at fusion (REP-103 TF frame, declared by the recording, given, or
estimated from the surface and the cameras), stored in the volume, and followed by segment and nbv.

The y-down test: the bundled sample (z-up world) is exported as frames, its poses turned by the rotation
taking z to -y (SUN3D's y-down world), imported without an up, and fused with the same grid settings; the
fused y-down volume must give the same support plane, the same object segments and the same NBV gains as the
z-up original.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, load_ternary, save_ternary
from kinfu_cli.fusion.up import choose_up, estimate_up, is_rep103_frame, view_axes, z_to_up_rotation
from kinfu_cli.fusion.volume import load_volume
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.rgbd_folders import export_frames
from kinfu_cli.io.world_up import WORLD_UP_TOPIC, WorldUp, read_world_up
from kinfu_cli.nbv.ranking import estimate_table_z, rank_poi
from kinfu_cli.nbv.viewpoints import SphereSpec, sphere_viewpoints

R_YDOWN = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # z -> -y, y -> z (SUN3D-like)
FUSE = ["--voxel-size", "0.01", "--size", "1.6", "--quiet"]


def up_warnings(report: dict) -> list[str]:
    """report.json warnings other than the grid-face one (these tests fuse small explicit grids on purpose)."""
    return [w for w in report["warnings"] if "touch the grid faces" not in w]
# a coarse viewing sphere (6 longitudes x 4 latitudes x 4 rolls) keeps the NBV comparison quick
SPHERE = ["--lon-step", "60", "--lat-step", "30", "--roll-step", "90", "--quiet"]


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def one_line_error(res, *needles):
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: "), res.output
    for n in needles:
        assert n in lines[0], (n, lines[0])


# ------------------------------------------------------------------------------------------- unit level
def test_rotation_taking_z_to_up():
    assert np.allclose(z_to_up_rotation((0, -1, 0)), R_YDOWN)
    for up in ([0, 0, 1], [0, 0, -1], [0.3, -0.8, 0.2], [1, 0, 0]):
        R = z_to_up_rotation(up)
        assert np.allclose(R @ [0, 0, 1], np.asarray(up) / np.linalg.norm(up))
        assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
    # the viewing sphere about up is the z-up sphere turned: same distances, latitudes above the table
    c = np.array([0.1, 0.2, 0.3])
    P = sphere_viewpoints(c, lon_step=90, lat_step=30, roll_step=90, up=(0, -1, 0))
    Pz = sphere_viewpoints(c, lon_step=90, lat_step=30, roll_step=90)
    assert np.allclose(P[:, :3, :3], R_YDOWN @ Pz[:, :3, :3])
    assert np.allclose(P[:, :3, 3] - c, (Pz[:, :3, 3] - c) @ R_YDOWN.T)
    assert np.all((P[:, :3, 3] - c) @ [0, -1, 0] >= -1e-9)


def test_plot_axes_are_right_handed_and_named_after_world_axes():
    for up, names in ((None, ("x", "y", "z")), ((0, -1, 0), ("x", "z", "-y")), ((0, 0, -1), ("y", "x", "-z"))):
        v = view_axes(up)
        assert v.names == names and np.allclose(np.cross(v.e1, v.e2), v.up)
    v = view_axes((0.2, -0.9, -0.4))
    assert v.axis is None and np.allclose(np.cross(v.e1, v.e2), v.up) and abs(v.e1 @ v.up) < 1e-12


def _floor_scene(up, n_cameras=12, wall=True, seed=0):
    """Points and normals of a 2 x 2 m floor (and a wall) in a world whose up is `up`, and cameras 1.2 m above
    it looking down by 50 deg from around the scene (their image-up is 50 deg from up)."""
    rng = np.random.default_rng(seed)
    R = z_to_up_rotation(up)
    floor = np.c_[rng.uniform(-1, 1, (4000, 2)), rng.normal(0, 0.003, 4000)]
    pts, nrm = [floor], [np.tile([0.0, 0.0, 1.0], (4000, 1))]
    if wall:  # a 2 x 1 m wall at x = 1 facing -x
        w = np.c_[np.full(2000, 1.0), rng.uniform(-1, 1, 2000), rng.uniform(0, 1, 2000)]
        pts.append(w)
        nrm.append(np.tile([-1.0, 0.0, 0.0], (2000, 1)))
    poses = []
    for a in np.linspace(0, 2 * np.pi, n_cameras, endpoint=False):
        pos = np.array([1.5 * np.cos(a), 1.5 * np.sin(a), 1.2])
        z = -pos / np.linalg.norm(pos)
        z = np.cos(np.radians(50)) * np.r_[z[:2] / np.linalg.norm(z[:2]), 0] - np.sin(np.radians(50)) * np.r_[0, 0, 1]
        x = np.cross(z, [0, 0, 1])
        x /= np.linalg.norm(x)
        T = np.eye(4)
        T[:3, :3] = np.c_[x, np.cross(z, x), z]
        T[:3, 3] = pos
        poses.append(T)
    poses = np.array(poses)
    poses[:, :3, :] = np.einsum("ij,njk->nik", R, poses[:, :3, :])
    return np.vstack(pts) @ R.T, np.vstack(nrm) @ R.T, poses


@pytest.mark.parametrize("up", [(0, 0, 1), (0, -1, 0), (0.3, -0.8, -0.5)])
def test_estimate_up_finds_the_plane_below_the_cameras_not_the_wall(up):
    pts, nrm, poses = _floor_scene(up)
    est, source, evidence = estimate_up(pts, nrm, poses)
    assert source == "estimated-plane" and angle_deg(est, up) < 1.0, evidence
    # the cameras alone lean 50 deg towards where they look; on one side of the scene they do not cancel
    cam_up = -poses[:3, :3, 1].mean(axis=0)
    assert 30 < angle_deg(cam_up, up) < 70
    est, source, evidence = estimate_up(pts, nrm, poses[:3])
    assert source == "estimated-plane" and angle_deg(est, up) < 1.0, evidence
    # without a floor the wall does not qualify (it faces the cameras, across their image-up)
    keep = np.abs(nrm @ (np.asarray(up) / np.linalg.norm(up))) < 0.5
    est, source, evidence = estimate_up(pts[keep], nrm[keep], poses[:3])
    assert source == "camera" and not any(p["qualifies"] for p in evidence["planes"])
    assert angle_deg(est, cam_up) < 1e-6


def test_choose_up_rules():
    pts, nrm, poses = _floor_scene((0, -1, 0))
    kw = dict(points=pts, normals=nrm, camera_poses=poses)
    assert is_rep103_frame("map") and is_rep103_frame("/robot1/odom") and not is_rep103_frame("camera_optical")
    # a REP-103 TF frame is z up; its y-down data is pointed out, not silently trusted nor overridden
    c = choose_up(world="world", world_from_tf=True, up_name="--up", **kw)
    assert c.source == "tf-rep103" and np.allclose(c.up, [0, 0, 1])
    assert len(c.warnings) == 1 and "90 deg from z" in c.warnings[0] and "--up" in c.warnings[0]
    # the same name from an imported folder (declared, without an up) is estimated
    c = choose_up(world="world", world_from_tf=True, declared=WorldUp("world", None), **kw)
    assert c.source == "estimated-plane" and angle_deg(c.up, (0, -1, 0)) < 1 and not c.warnings
    c = choose_up(world="world", world_from_tf=True, declared=WorldUp("world", np.array([0.0, -1, 0])), **kw)
    assert c.source == "recording" and np.allclose(c.up, [0, -1, 0])
    # a declaration about another frame than the poses' (ICP from the first camera) does not apply
    c = choose_up(world="", declared=WorldUp("world", np.array([0.0, 1, 0])), **kw)
    assert c.source == "estimated-plane" and angle_deg(c.up, (0, -1, 0)) < 1
    c = choose_up(option=np.array([1.0, 0, 0]), world="world", world_from_tf=True, **kw)
    assert c.source == "option" and np.allclose(c.up, [1, 0, 0])
    c = choose_up(init_up=np.array([0.0, 1, 0]), init_source="recording", **kw)
    assert c.source == "recording" and np.allclose(c.up, [0, 1, 0])
    # ICP's first camera (no TF frame), a frame that is not REP-103: estimated; nothing at all: unknown
    assert choose_up(world="", **kw).source == "estimated-plane"
    assert choose_up(world="vicon", world_from_tf=True, **kw).source == "estimated-plane"
    c = choose_up(world="", camera_poses=np.zeros((0, 4, 4)))
    assert c.up is None and c.source == "unknown" and c.warnings


def test_table_height_along_up_on_a_turned_grid():
    n, vs = 40, 0.02
    lab = np.full((n, n, n), EMPTY, np.int8)
    lab[:, :, :10] = UNKNOWN
    lab[:, :, 10] = OCCUPIED  # table top at z = 0.20..0.22
    lab[:, :, 4] = OCCUPIED  # a floor below
    g = TernaryGrid(lab, np.zeros(3), vs)
    assert estimate_table_z(g) == pytest.approx(0.22)
    # the same grid in a y-down world: voxel (i, j, k) -> (i, n - 1 - k, j)
    g2 = TernaryGrid(lab.transpose(0, 2, 1)[:, ::-1, :], np.array([0.0, -n * vs, 0.0]), vs, up=(0, -1, 0))
    assert estimate_table_z(g2, up=g2.up) == pytest.approx(0.22)
    # an up a hair off the axis takes the general path and agrees within a voxel
    assert estimate_table_z(g2, up=(1e-4, -1, 0)) == pytest.approx(0.22, abs=vs)
    cam = CameraModel(40.0, 40.0, 19.5, 14.5, 40, 30, min_range=0.2)
    poi = np.array([0.4, 0.4, 0.3])
    sph = SphereSpec(radius=0.3, lon_step=90, lat_step=45, roll_step=180)
    r1 = rank_poi(g, poi, cam, sphere=sph, table_z=0.22)
    r2 = rank_poi(g2, R_YDOWN @ poi, cam, sphere=sph, table_z=0.22, up=(0, -1, 0))
    assert r1.scores.rejected() == r2.scores.rejected() and r1.scores.valid.sum() > 0
    assert np.allclose(r1.scores.gain, r2.scores.gain)


# ------------------------------------------------------------------------------------------- y-down copy
@pytest.fixture(scope="module")
def zup_ydown(sample_dir, tmp_path_factory):
    """The sample fused as recorded (z up) and its y-down copy (frames exported, poses turned by R_YDOWN,
    imported without an up, fused with the same grid settings)."""
    tmp = tmp_path_factory.mktemp("up")
    res = run("fuse", sample_dir / "recording.mcap", "-o", tmp / "z", *FUSE)
    assert res.exit_code == 0, res.output
    export_frames(sample_dir / "recording.mcap", tmp / "frames")
    for p in (tmp / "frames").glob("*.pose.txt"):
        T = np.loadtxt(p)
        T[:3, :] = R_YDOWN @ T[:3, :]
        np.savetxt(p, T, fmt="%.17g")
    res = run("import", tmp / "frames", "-o", tmp / "ydown.mcap", "--json", "-q")
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["up"] is None
    res = run("fuse", tmp / "ydown.mcap", "-o", tmp / "y", *FUSE)
    assert res.exit_code == 0, res.output
    gt = json.loads((sample_dir / "ground_truth" / "changes.json").read_text())
    centres = [o["center"] for o in gt["objects"] if o.get("present_after")]
    for name, R in (("z", np.eye(3)), ("y", R_YDOWN)):
        (tmp / f"pois_{name}.json").write_text(json.dumps(
            {"pois": [{"id": i, "position": (R @ c).tolist(), "radius": 0.15} for i, c in enumerate(centres)]}))
    return tmp


def test_up_is_decided_at_fusion_and_stored_everywhere(zup_ydown):
    tmp = zup_ydown
    rz = json.loads((tmp / "z" / "report.json").read_text())
    ry = json.loads((tmp / "y" / "report.json").read_text())
    # the sample's TF world follows REP-103; the data agree (the table is level in it)
    assert rz["up"] == [0.0, 0.0, 1.0] and rz["up_source"] == "tf-rep103"
    assert angle_deg(rz["up_evidence"]["estimate"]["up"], [0, 0, 1]) < 1 and not up_warnings(rz)
    # the imported copy's "world" is declared not REP-103: up comes from the table below the cameras
    with open_recording(tmp / "ydown.mcap") as rec:
        declared = read_world_up(rec)
        assert WORLD_UP_TOPIC in rec.topics
    assert declared.frame == "world" and declared.up is None
    assert ry["up_source"] == "estimated-plane" and angle_deg(ry["up"], [0, -1, 0]) < 0.5
    plane = ry["up_evidence"]["plane"]
    assert plane["cameras_above"] == 1.0 and plane["points_fraction"] > 0.3 and plane["angle_to_camera_up_deg"] < 75
    for name, report in (("z", rz), ("y", ry)):
        vol = load_volume(tmp / name / "volume.npz")
        assert np.allclose(vol.up, report["up"]) and vol.up_source == report["up_source"]
        assert np.allclose(load_ternary(tmp / name / "ternary.npz").up, report["up"])
        assert vol.intrinsics == report["intrinsics"] == {"fx": 292.5, "fy": 292.5, "cx": 159.5, "cy": 119.5,
                                                          "width": 320, "height": 240}


def _segments(path, *args):
    # --no-color: these tests compare shape segmentation across world frames; colour moves a few more foot
    # points of the smallest object to the table on one copy than the other (63 vs 50 points, beyond rel=0.2)
    res = run("segment", path, "-o", path.parent / ("seg" + "".join(args).replace(",", "_")), "--json",
              "--no-superquadrics", "--quiet", "--no-color", *args)
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout), res


def test_segment_on_the_ydown_copy_finds_the_table_and_the_same_objects(zup_ydown):
    tmp = zup_ydown
    dz, _ = _segments(tmp / "z" / "volume.npz")
    dy, _ = _segments(tmp / "y" / "volume.npz")
    objs = {k: [s for s in d["segments"] if s["kind"] == "object"] for k, d in (("z", dz), ("y", dy))}
    assert dz["up_source"] == dy["up_source"] == "volume" and not dz["warnings"] and not dy["warnings"]
    assert dz["support_plane"] is not None and dy["support_plane"] is not None
    assert angle_deg(dy["support_plane"][:3], [0, -1, 0]) < 1 and angle_deg(dz["support_plane"][:3], [0, 0, 1]) < 1
    assert dz["support_plane"][3] == pytest.approx(dy["support_plane"][3], abs=0.005)  # table 0.70 m up
    assert len(objs["z"]) == len(objs["y"]) >= 4
    # each segment of the z-up volume (but specks) is in the y-down one, in the same place (turned by R) with
    # about the same points (supervoxel seeds and surface thinning sit on world-axis grids: counts differ a little)
    big = [s for s in objs["z"] if s["point_count"] >= 50]
    assert len(big) >= 4
    for sz in big:
        c = R_YDOWN @ sz["centroid"]
        sy = min(objs["y"], key=lambda s: np.linalg.norm(np.asarray(s["centroid"]) - c))
        assert np.linalg.norm(sy["centroid"] - c) < 0.015
        assert sy["point_count"] == pytest.approx(sz["point_count"], rel=0.2)


def test_ignoring_up_on_the_ydown_copy_is_an_empty_result_with_a_warning(zup_ydown):
    tmp = zup_ydown
    doc, res = _segments(tmp / "y" / "volume.npz", "--up", "0,0,1")
    assert doc["support_plane"] is None and doc["up_source"] == "option"
    said = [w for w in doc["warnings"] if "touch the grid's faces" not in w]  # objects the 1 m grid cuts: said too
    assert len(said) == 2 and said[0].startswith("no support plane: of ")
    assert said[1].startswith("the given up [0.0, 0.0, 1.0] is 90 deg from the volume's up")
    assert "kinfu: warning: no support plane" in res.stderr
    res = run("segment", tmp / "y" / "volume.npz", "-o", tmp / "seg_z_text", "--up", "0,0,1", "--no-superquadrics")
    assert res.exit_code == 0 and "segments, no support plane from" in res.stdout, res.output


def test_nbv_on_the_ydown_copy_gives_the_z_up_gains(zup_ydown):
    tmp = zup_ydown
    docs = {}
    for name in ("z", "y"):
        res = run("nbv", tmp / name / "volume.npz", "--pois", tmp / f"pois_{name}.json", "--json", *SPHERE)
        assert res.exit_code == 0, res.output
        docs[name] = json.loads(res.stdout)
    dz, dy = docs["z"], docs["y"]
    assert dz["camera_source"] == dy["camera_source"] == "volume" and dz["camera"]["fx"] == 292.5
    assert dz["up_source"] == dy["up_source"] == "volume" and not dz["warnings"] and not dy["warnings"]
    assert dz["table_z"] == pytest.approx(dy["table_z"], abs=0.011)
    gains = [(pz["best_gain"], py["best_gain"]) for pz, py in zip(dz["pois"], dy["pois"])]
    assert sum(g for g, _ in gains) > 100
    for pz, py in zip(dz["pois"], dy["pois"]):
        assert pz["valid"] == py["valid"] and pz["rejected"] == py["rejected"]
        assert py["best_gain"] == pytest.approx(pz["best_gain"], rel=0.02, abs=2), gains
    # every candidate below the table: no view, said as a warning with the counts (exit 0, JSON too)
    res = run("nbv", tmp / "y" / "volume.npz", "--pois", tmp / "pois_y.json", "--json", "--table-z", "5", *SPHERE)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert len(doc["warnings"]) == len(doc["pois"]) and all(p["valid"] == 0 for p in doc["pois"])
    assert "all 96 candidate views rejected (below_table 96)" in doc["warnings"][0]
    assert "the table is at height 5.000 m along up [" in doc["warnings"][0] and "(the volume's)" in doc["warnings"][0]
    assert res.stderr.count("kinfu: warning: POI") == len(doc["pois"])
    loud = [a for a in SPHERE if a != "--quiet"]  # --quiet prints only warnings and errors
    res = run("nbv", tmp / "y" / "volume.npz", "--pois", tmp / "pois_y.json", "--table-z", "5", *loud)
    assert "no valid view to rank" in res.stdout


def test_nbv_objects_mode_with_every_candidate_rejected_says_so(zup_ydown):
    res = run("nbv", zup_ydown / "y" / "volume.npz", "--mode", "objects", "--json", "--table-z", "5", "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["pose"] is None and doc["empty_reason"].startswith("objects: all ")
    assert doc["candidates_rejected"]["below_table"] > 0 and doc["warnings"] == [doc["empty_reason"]]
    assert "kinfu: warning: objects: all" in res.stderr


def test_import_up_is_declared_and_wins(zup_ydown):
    tmp = zup_ydown
    res = run("import", tmp / "frames", "-o", tmp / "ydown_up.mcap", "--up", "0,-2,0", "--json", "-q")
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["up"] == [0.0, -1.0, 0.0]
    res = run("fuse", tmp / "ydown_up.mcap", "-o", tmp / "y_up", "--every", "6", *FUSE)
    assert res.exit_code == 0, res.output
    r = json.loads((tmp / "y_up" / "report.json").read_text())
    assert r["up"] == [0.0, -1.0, 0.0] and r["up_source"] == "recording"
    # fuse --up wins over everything
    res = run("fuse", tmp / "ydown_up.mcap", "-o", tmp / "y_opt", "--every", "6", "--up", "1,0,0", *FUSE)
    assert res.exit_code == 0, res.output
    r = json.loads((tmp / "y_opt" / "report.json").read_text())
    assert r["up"] == [1.0, 0.0, 0.0] and r["up_source"] == "option"


# ------------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("value", ["nan,0,1", "0,inf,1", "0,0,0", "1,2", "up"])
def test_non_finite_or_zero_up_is_a_one_line_error(tmp_path, sample_dir, value):
    g = TernaryGrid(np.zeros((4, 4, 4), np.int8), np.zeros(3), 0.1)
    save_ternary(tmp_path / "t.npz", g)
    one_line_error(run("segment", tmp_path / "t.npz", "-o", tmp_path / "s", "--up", value), "--up:")
    one_line_error(run("fuse", sample_dir / "recording.mcap", "-o", tmp_path / "f", "--up", value), "--up:")
    one_line_error(run("nbv", tmp_path / "t.npz", "--mode", "objects", "--up", value), "--up:")
    assert not (tmp_path / "s").exists() and not (tmp_path / "f").exists()


def test_nbv_without_recorded_intrinsics_warns_about_the_kinect_preset(tmp_path):
    lab = np.full((40, 40, 40), EMPTY, np.int8)
    lab[:, :, :10] = UNKNOWN
    lab[:, :, 10] = OCCUPIED
    lab[18:22, 18:22, 11:15] = UNKNOWN
    save_ternary(tmp_path / "t.npz", TernaryGrid(lab, np.zeros(3), 0.04))
    (tmp_path / "p.json").write_text(json.dumps({"pois": [{"id": 0, "position": [0.8, 0.8, 0.5]}]}))
    res = run("nbv", tmp_path / "t.npz", "--pois", tmp_path / "p.json", "--json", *SPHERE)
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["camera_source"] == "kinect_v1 preset" and doc["camera"]["fx"] == 525.0
    assert doc["up_source"] == "assumed-z" and doc["up"] == [0.0, 0.0, 1.0]
    assert len(doc["warnings"]) == 1 and "Kinect v1 preset" in doc["warnings"][0]
    assert "kinfu: warning: the volume does not record the camera" in res.stderr


# ------------------------------------------------------------------------------------------- real data
@pytest.mark.shared_data
def test_real_tabletop_box_first_camera_world_has_its_table(shared_data, tmp_path):
    """rgbd-tabletop-box: poses relative to the first camera (y down, z forward), a box on its side filling
    the view: the table is found below the cameras and segment finds it with the default settings."""
    folder = shared_data("rgbd-tabletop-box")
    res = run("import", folder, "-o", tmp_path / "box.mcap", "-q")
    assert res.exit_code == 0, res.output
    res = run("fuse", tmp_path / "box.mcap", "-o", tmp_path / "f", "--voxel-size", "0.005", "--size", "1.5", "--quiet")
    assert res.exit_code == 0, res.output
    r = json.loads((tmp_path / "f" / "report.json").read_text())
    assert r["up_source"] == "estimated-plane" and not up_warnings(r)
    # the first camera looks ~20 deg down at the desk: up is near its -y axis, tilted towards -z
    assert angle_deg(r["up"], [0, -1, 0]) < 30 and r["up"][2] < -0.2
    assert r["intrinsics"]["fx"] == pytest.approx(615.195, abs=1e-3) and r["intrinsics"]["width"] == 640
    res = run("segment", tmp_path / "f" / "volume.npz", "-o", tmp_path / "s", "--json", "--no-superquadrics",
              "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    # the 1.5 m grid cuts two objects (fuse warns that they touch its faces): segment says so, and nothing else
    assert doc["support_plane"] is not None and doc["up_source"] == "volume"
    assert len(doc["warnings"]) == 1 and "touch the grid's faces" in doc["warnings"][0]
    assert angle_deg(doc["support_plane"][:3], r["up"]) < 5
    assert doc["stats"]["plane_points"] > 0.05 * doc["points"]
    assert len([s for s in doc["segments"] if s["kind"] == "object"]) >= 3
