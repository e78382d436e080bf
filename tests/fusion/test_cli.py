"""`kinfu fuse` end to end on the sample recordings, and its one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.grid import load_ternary
from kinfu_cli.fusion.tracking import MAX_CONDITION
from kinfu_cli.fusion.volume import load_volume

FAST = ["--voxel-size", "0.02", "--size", "2.0", "--quiet"]


def run(args):
    return CliRunner().invoke(cli, ["fuse", *args])


@pytest.fixture(scope="module")
def fused(sample_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("fuse") / "out"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), *FAST, "--plot"])
    assert res.exit_code == 0, res.output
    return out


def test_outputs_and_report_are_consistent(fused, sample_dir):
    for name in ("mesh.ply", "cloud.ply", "volume.npz", "ternary.npz", "report.json", "slices_xy.png"):
        assert (fused / name).stat().st_size > 0, name
    report = json.loads((fused / "report.json").read_text())
    grid = load_ternary(fused / "ternary.npz")
    assert report["counts"] == grid.counts()
    assert sum(report["counts"].values()) == int(np.prod(grid.shape)) == int(np.prod(report["grid"]["shape"]))
    lines = (sample_dir / "ground_truth" / "camera_poses.txt").read_text().splitlines()
    n_depth = len([ln for ln in lines if ln.strip() and not ln.startswith("#")])
    f = report["frames"]
    assert f["used"] + f["dropped_total"] + f["skipped_every"] == f["depth_messages"] == n_depth
    assert report["pose_mode"] == "forced" and report["tracking"] is None
    assert set(report["timing_s"]) >= {"read", "integrate", "extract", "write", "total"}
    # the volume file continues where ternary.npz stopped
    assert np.array_equal(load_volume(fused / "volume.npz").labels(), grid.labels)


def test_table_and_objects_where_ground_truth_says(fused, sample_dir):
    gt = json.loads((sample_dir / "ground_truth" / "changes.json").read_text())
    grid = load_ternary(fused / "ternary.npz")
    occ = np.argwhere(grid.labels == 1)
    pts = grid.centers(occ)
    table_z = -gt["table"]["plane"][3]
    # most occupied voxels are on the table top (or the floor) plane
    on_table = np.abs(pts[:, 2] - table_z) < 0.03
    assert on_table.mean() > 0.2
    # an object present at the end is occupied near its centre's top
    for obj in gt["objects"]:
        if obj.get("present_after"):
            c = np.asarray(obj["center"])
            near = np.linalg.norm(pts - c, axis=1) < max(obj["size"]) + 0.03
            assert near.sum() > 5, obj["id"]


@pytest.mark.parametrize("name", ["recording.bag", "recording_ros2"])
def test_bag_and_ros2_give_the_same_volume_as_mcap(fused, sample_dir, tmp_path, name):
    out = tmp_path / "bag"
    res = run([str(sample_dir / name), "-o", str(out), *FAST])
    assert res.exit_code == 0, res.output
    a = load_ternary(fused / "ternary.npz").labels
    b = load_ternary(out / "ternary.npz").labels
    assert (a == b).mean() > 0.999


def test_continue_clear_and_json(fused, sample_dir, tmp_path):
    out = tmp_path / "cont"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), "--init", str(fused / "volume.npz"),
               "--start", "0", "--end", "1.0", "--clear-sphere", "0.0,0.0,0.75,0.15", "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)  # stderr has the warning that the 2 m grid cuts the scene
    assert report["grid"]["placement"].startswith("--init")
    assert report["cleared_spheres"][0]["radius"] == 0.15
    assert report["frames"]["used"] < json.loads((fused / "report.json").read_text())["frames"]["used"]


@pytest.mark.parametrize("args, msg", [
    (["--pose", "topic"], "--pose-topic"),
    (["--voxel-size", "0.0005", "--size", "20"], "would need up to"),
    (["--clear-sphere", "1,2,3"], "--clear-sphere"),
    (["--clear-sphere", "0,0,0,1e300"], "--clear-sphere"),
    (["--voxel-size", "0.01", "--resolution", "64"], "not both"),
    (["--init", "/nonexistent/volume.npz"], "no such volume"),
    (["--every", "0"], "--every"),
    (["--start", "5", "--end", "1"], "--start"),
])
def test_bad_options_exit_2_without_outputs(sample_dir, tmp_path, args, msg):
    out = tmp_path / "out"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), "--quiet", *args])
    assert res.exit_code == 2, res.output
    assert "kinfu: error:" in res.output and msg in res.output
    assert "Traceback" not in res.output
    assert not out.exists() or not any(out.iterdir())


def test_missing_recording_and_empty_depth(tmp_path):
    out = tmp_path / "out"
    res = run([str(tmp_path / "missing.mcap"), "-o", str(out), "--quiet"])
    assert res.exit_code == 2 and "kinfu: error:" in res.output
    assert not out.exists()


def test_depth_range_excluding_everything_is_an_error(sample_dir, tmp_path):
    out = tmp_path / "out"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), *FAST, "--min-depth", "3.5", "--max-depth", "4"])
    assert res.exit_code == 2, res.output
    assert "no usable depth frames" in res.output
    assert not out.exists() or not any(out.iterdir())


def test_a_time_window_without_frames_says_so_when_sizing_the_grid(sample_dir, tmp_path):
    """The grid sizing pass (--size auto, the default) used to blame --size and the depth range."""
    out = tmp_path / "out"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), "--quiet", "--start", "0.001", "--end", "0.002"])
    assert res.exit_code == 2, res.output
    assert "no depth frames in the selection" in res.output and "--size" not in res.output
    assert not out.exists() or not any(out.iterdir())


def test_imported_7scenes_fuses_forced_and_icp(shared_data, tmp_path):
    """`kinfu import` of the real 7-Scenes frames, then `kinfu fuse` with TF poses and with ICP tracking."""
    root = shared_data("rgbd-7scenes-redkitchen")
    rec = tmp_path / "redkitchen.mcap"
    # every 6th of frames 0-59: the same 2 s of camera motion in 10 frames (ICP still tracks 0.2 s steps)
    res = CliRunner().invoke(cli, ["import", str(root), "-o", str(rec), "--frames", "0:60:6"])
    assert res.exit_code == 0, res.output
    forced = tmp_path / "forced"
    res = run([str(rec), "-o", str(forced), "--voxel-size", "0.015", "--quiet"])
    assert res.exit_code == 0, res.output
    rf = json.loads((forced / "report.json").read_text())
    assert rf["pose_mode"] == "forced" and rf["frames"]["used"] == 10
    assert rf["counts"]["occupied"] > 10000 and rf["mesh"]["triangles"] > 10000
    icp = tmp_path / "icp"
    origin = ",".join(str(v) for v in rf["grid"]["origin"])  # same grid, so labels compare voxel by voxel
    res = run([str(rec), "-o", str(icp), "--voxel-size", "0.015", "--pose", "icp", "--origin", origin, "--quiet"])
    assert res.exit_code == 0, res.output
    ri = json.loads((icp / "report.json").read_text())
    track = ri["tracking"]["frames"]
    assert len(track) == 9 and ri["tracking"]["lost"] == 0
    # the recording has colour: every frame's ICP had the colour term against the frame fused before it
    assert ri["tracking"]["photometric"] == 9 and all(t["photometric"] for t in track)
    # each tracked frame says how well its view pinned the pose down (the kitchen reads 1e2-1e3)
    assert all(10 < t["condition"] < MAX_CONDITION for t in track)
    truth = [np.loadtxt(root / f"frame-{i:06d}.pose.txt") for i in range(6, 60, 6)]
    err = [np.linalg.norm(np.asarray(t["T_world_camera"])[:3, 3] - g[:3, 3]) for t, g in zip(track, truth)]
    still = [np.linalg.norm(truth[0][:3, 3] - g[:3, 3]) for g in truth]
    assert np.sqrt(np.mean(np.square(err))) < 0.25 * np.sqrt(np.mean(np.square(still)))
    # the two volumes agree on most observed voxels
    a = load_ternary(forced / "ternary.npz").labels
    b = load_ternary(icp / "ternary.npz").labels
    seen = (a != 0) | (b != 0)
    assert (a == b)[seen].mean() > 0.9


def test_hint_mode_tracks_close_to_the_tf_poses(sample_dir, tmp_path):
    out = tmp_path / "hint"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), "--voxel-size", "0.01", "--size", "2.0",
               "--quiet", "--pose", "hint", "--every", "3"])
    assert res.exit_code == 0, res.output
    r = json.loads((out / "report.json").read_text())
    t = r["tracking"]
    assert r["pose_mode"] == "hint" and len(t["frames"]) == r["frames"]["used"] - 1 and t["lost"] == 0
    # ICP fails only where the view pins the pose down poorly (this 2 m grid cuts the last views' scene): that frame
    # is fused at its TF pose
    assert all("pins the pose down poorly" in f["reason"] for f in t["frames"] if f["tf_fallback"])
    # the synthetic TF poses are exact: ICP started there stays within a centimetre
    dev = [f["given_minus_tracked_m"] for f in t["frames"] if not f["tf_fallback"]]
    assert len(dev) >= 0.8 * len(t["frames"]) and np.median(dev) < 0.01


def test_hint_mode_with_exact_tf_does_not_drift_over_the_recording(sample_dir, tmp_path):
    # every frame, through the scene change: ICP started at the exact TF pose must not walk away from it (the
    # coarse pyramid levels slid each frame ~1 cm along the table: 5 cm RMS, 15 cm at the end)
    out = tmp_path / "hint"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), "--quiet", "--pose", "hint"])
    assert res.exit_code == 0, res.output
    t = json.loads((out / "report.json").read_text())["tracking"]
    assert t["lost"] == 0 and t["ate_vs_given_m"]["rmse"] < 0.015 and t["ate_vs_given_m"]["max"] < 0.04


def test_hint_mode_on_a_wrong_camera_frame_says_the_tf_is_suspect(sample_dir, tmp_path):
    # link3 is in the TF tree but is not the camera: ICP puts the frames 0.2-1.4 m from their TF poses, refused
    res = run([str(sample_dir / "recording.mcap"), "-o", str(tmp_path / "out"), "--quiet", "--pose", "hint",
               "--camera-frame", "link3"])
    assert res.exit_code == 2, res.output
    assert res.output.count("kinfu: error:") == 1 and "check the camera frame and the TF chain" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "out" / "report.json").exists()


def test_clear_pois_forgets_spheres_after_fusing(sample_dir, tmp_path):
    pois = tmp_path / "pois.json"
    center, radius = [0.03, 0.14, 0.77], 0.12  # around obj1 on the table
    pois.write_text(json.dumps({"pois": [{"position": center, "radius": radius}]}))
    out = tmp_path / "out"
    res = run([str(sample_dir / "recording.mcap"), "-o", str(out), *FAST, "--clear-pois", str(pois)])
    assert res.exit_code == 0, res.output
    grid = load_ternary(out / "ternary.npz")
    idx = np.indices(grid.shape).reshape(3, -1).T
    d = np.linalg.norm(grid.centers(idx) - center, axis=1).reshape(grid.shape)
    assert np.all(grid.labels[d < radius] == 0)
    assert np.count_nonzero(grid.labels[(d > radius + 0.04) & (d < radius + 0.15)] == 1) > 20
    r = json.loads((out / "report.json").read_text())
    assert r["cleared_spheres"][0]["radius"] == radius
    bad = tmp_path / "bad.json"
    bad.write_text("{\"pois\": [{\"position\": [1, 2]}]}")
    res = run([str(sample_dir / "recording.mcap"), "-o", str(tmp_path / "o2"), *FAST, "--clear-pois", str(bad)])
    assert res.exit_code == 2 and "position" in res.output and not (tmp_path / "o2").exists()


def test_world_frame_is_recorded_and_checked(fused, sample_dir, tmp_path):
    """The frame the poses came in travels with the volume: report, volume.npz, ternary.npz. Fusing into a
    volume of another frame is refused; POIs of another frame give a warning (they may be calibrated)."""
    from kinfu_cli.fusion.volume import load_volume as load

    report = json.loads((fused / "report.json").read_text())
    # the 2 m grid cuts the sample's floor (a warning of its own); nothing about frames
    assert report["world_frame"] == "world"
    assert [w for w in report["warnings"] if not w.startswith("occupied voxels touch the grid faces")] == []
    assert load(fused / "volume.npz").frame == "world"
    assert load_ternary(fused / "ternary.npz").frame == "world"

    pois = tmp_path / "pois.json"
    pois.write_text(json.dumps({"frame": "polhemus_base", "pois": [{"position": [0.03, 0.14, 0.77], "radius": 0.1}]}))
    res = CliRunner().invoke(cli, ["fuse", str(sample_dir / "recording.mcap"), "-o", str(tmp_path / "o1"), *FAST,
                                   "--clear-pois", str(pois)])
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: --clear-pois" in res.stderr and "'polhemus_base'" in res.stderr
    assert json.loads((tmp_path / "o1" / "report.json").read_text())["warnings"][0].startswith("--clear-pois")

    vol = load(fused / "volume.npz")
    vol.frame = "odom"
    vol.save(tmp_path / "odom.npz")
    res = run([str(sample_dir / "recording.mcap"), "-o", str(tmp_path / "o2"), *FAST, "--init",
               str(tmp_path / "odom.npz")])
    assert res.exit_code == 2 and "--init" in res.output and "'odom'" in res.output and "'world'" in res.output
    assert not (tmp_path / "o2").exists()
