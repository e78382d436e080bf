"""The robot chain, the scenario and `kinfu synth`: files, determinism, round trip through every container."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.poses import look_at
from kinfu_cli.sim.robot import RobotArm
from kinfu_cli.sim.scenario import depth_to_mm, make_scenario

SMALL = dict(width=64, height=48, frames=6)


def test_robot_chain_reaches_the_scan_poses_exactly():
    sc = make_scenario(3, "place", **SMALL)
    robot = sc.robot
    for f in sc.frames:
        # composing the published transforms gives the camera pose
        T = {}
        for parent, child, M in robot.static_transforms() + robot.joint_transforms(f.q):
            T[child] = (parent, M)
        chain, frame = np.eye(4), "camera_optical"
        while frame != "world":
            parent, M = T[frame]
            chain = M @ chain
            frame = parent
        assert np.abs(chain - f.T_world_camera).max() < 1e-12
        assert np.abs(robot.fk(robot.ik(f.T_world_camera)) - f.T_world_camera).max() < 1e-9
    with pytest.raises(ConfigError, match="out of the arm's reach"):
        RobotArm().ik(look_at((3.0, -3.0, 2.0), (0.0, 0.0, 0.7)))


@pytest.mark.parametrize("kind", ["place", "remove", "pick-and-place"])
def test_scenarios_change_the_scene_where_the_hand_pauses(kind):
    sc = make_scenario(1, kind, **SMALL)
    n_changes = 2 if kind == "pick-and-place" else 1
    assert len(sc.changes) == len(sc.hand_changes) == n_changes
    before = {o.id: o for o in sc.scene_before.objects if o.present}
    after = {o.id: o for o in sc.scene_after.objects if o.present}
    if kind == "place":
        assert len(after) == len(before) + 1
    elif kind == "remove":
        assert len(after) == len(before) - 1
    else:
        moved = [i for i in before if before[i].center != after[i].center]
        assert len(moved) == 1 and np.linalg.norm(np.subtract(before[moved[0]].center, after[moved[0]].center)) > 0.3
    for c, hc in zip(sc.changes, sc.hand_changes):
        assert np.allclose(c["hand_position"], hc.position)
        assert np.linalg.norm(np.subtract(c["hand_position"], c["position"])) < 0.2   # inside the POI radius
        pause = (sc.hand.t >= hc.t_start) & (sc.hand.t <= hc.t_end)
        assert np.linalg.norm(sc.hand.positions[pause] - hc.position, axis=1).max() < 0.02
    scan = [f for f in sc.frames if f.phase == "scan"]
    assert all(f.stamp_ns < sc.t0_ns + sc.hand.t[0] * 1e9 for f in scan)
    assert all(f.stamp_ns > sc.t0_ns + sc.hand.t[-1] * 1e9 for f in sc.frames if f.phase == "after")
    # the after-change views look at the change: its position projects inside the image
    for f in sc.frames:
        if f.phase == "after":
            p = np.linalg.inv(f.T_world_camera) @ np.r_[np.mean([c["position"] for c in sc.changes], 0), 1.0]
            u, v = (sc.K @ p[:3])[:2] / p[2]
            assert p[2] > 0.3 and 0 <= u < sc.width and 0 <= v < sc.height


def test_scenario_is_deterministic():
    a, b = make_scenario(5, **SMALL), make_scenario(5, **SMALL)
    for i in (0, len(a.frames) - 1):
        fa, fb = a.render(i), b.render(i)
        assert np.array_equal(fa.depth, fb.depth) and np.array_equal(fa.color, fb.color)
    assert np.array_equal(a.hand.positions, b.hand.positions)
    assert a.changes == b.changes


def test_synth_writes_every_file_and_round_trips_through_each_container(tmp_path):
    from kinfu_cli.io.frames import iter_frames
    from kinfu_cli.io.hand import load_hand_trajectory
    from kinfu_cli.io.polhemus import read_polhemus
    from kinfu_cli.io.recording import open_recording

    out = tmp_path / "synth"
    res = CliRunner().invoke(cli, ["synth", "-o", str(out), "--width", "64", "--height", "48", "--frames", "6",
                                   "--seed", "2", "--json", "-q"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    gt = out / "ground_truth"
    for name in ("recording.mcap", "recording.bag", "recording_ros2/metadata.yaml", "ground_truth/scene_before.ply",
                 "ground_truth/scene_after.ply", "ground_truth/objects/table.ply", "ground_truth/changes.json",
                 "ground_truth/camera_poses.txt", "ground_truth/hand.traj"):
        assert (out / name).exists(), name
    changes = json.loads((gt / "changes.json").read_text())
    assert set(changes) >= {"changes", "objects", "table", "camera", "seed"} and changes["seed"] == 2
    assert [c["kind"] for c in changes["changes"]] == ["pick", "place"]
    for o in changes["objects"]:
        assert (gt / "objects" / f"{o['id']}.ply").exists() == o["present_after"]
    poses = np.loadtxt(gt / "camera_poses.txt")
    assert poses.shape == (6, 17)
    K = np.array(changes["camera"]["K"])

    sc = make_scenario(2, "pick-and-place", **SMALL)   # the same scenario, rebuilt in memory
    truth_mm = [depth_to_mm(sc.render(i).depth) for i in range(len(sc.frames))]
    assert np.allclose(poses[:, 1:].reshape(-1, 4, 4), [f.T_world_camera for f in sc.frames], atol=1e-8)
    for rec_path in summary["recordings"]:
        with open_recording(rec_path) as rec:
            frames = list(iter_frames(rec))
        assert len(frames) == 6, rec_path
        for f, row, mm in zip(frames, poses, truth_mm):
            assert abs(f.stamp_ns / 1e9 - row[0]) < 1e-6
            assert np.array_equal(np.round(f.depth * 1000).astype(np.uint16), mm), rec_path   # mm-exact
            assert np.allclose(f.K, K, atol=1e-9)
            assert np.abs(f.T_world_camera - row[1:].reshape(4, 4)).max() < 1e-8
            assert f.color is not None and f.color.shape == (48, 64, 3)
        hand = load_hand_trajectory(rec_path)
        assert np.abs(hand.positions - sc.hand.positions).max() < 1e-9
    traj = read_polhemus(gt / "hand.traj")
    assert abs(traj.duration - sc.hand.duration) < 0.011
    assert np.abs(traj.positions[0] - sc.hand.positions[0]).max() < 1e-5


@pytest.mark.parametrize("args, message", [
    (["--formats", "mcap,zip"], "--formats"),
    (["--frames", "1"], "--frames"),
    (["--width", "4"], "--width"),
    (["--n-objects", "40"], "--n-objects"),
    (["--hand-rate", "0"], "--hand-rate"),
])
def test_bad_options_are_one_line_errors(tmp_path, args, message):
    out = tmp_path / "o"
    res = CliRunner().invoke(cli, ["synth", "-o", str(out), "-q"] + args)
    assert res.exit_code == 2
    assert res.output.strip().splitlines()[-1].startswith("kinfu: error: ") and message in res.output
    assert "Traceback" not in res.output
    assert not out.exists() or not any(out.iterdir())


def test_output_that_is_a_file_is_an_error(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    res = CliRunner().invoke(cli, ["synth", "-o", str(f), "-q", "--frames", "2", "--width", "16", "--height", "12"])
    assert res.exit_code == 2 and "is a file" in res.output and "Traceback" not in res.output


def test_committed_sample_data_is_what_the_generator_makes(sample_dir):
    """sample_data/tabletop is reproducible from its README command (same ground truth, mm-exact depth)."""
    from kinfu_cli.io.frames import iter_frames
    from kinfu_cli.io.recording import open_recording
    from kinfu_cli.sim.scenario import load_ground_truth

    gt = load_ground_truth(sample_dir)
    info = gt.info
    sc = make_scenario(info["seed"], info["scenario"], width=gt.width, height=gt.height,
                       frames=info["frames"]["count"])
    assert np.allclose(gt.poses, [f.T_world_camera for f in sc.frames], atol=1e-8)
    assert np.allclose(gt.change_positions, [c["position"] for c in sc.changes])
    assert 5e6 > (sample_dir / "recording.mcap").stat().st_size
    check = {0, info["frames"]["scan"], info["frames"]["count"] - 1}
    with open_recording(sample_dir / "recording.mcap") as rec:
        for f in iter_frames(rec):
            if f.index in check:
                assert np.array_equal(np.round(f.depth * 1000).astype(np.uint16), depth_to_mm(sc.render(f.index).depth))
                check.discard(f.index)
    assert not check
    hand = gt.hand()
    assert abs(hand.t[0] - sc.hand.t[0]) < 1e-9 and np.abs(hand.positions[0] - sc.hand.positions[0]).max() < 1e-5
    after = gt.mesh("after")
    assert len(after.triangles) > 1000 and set(gt.object_meshes()) >= {"table", "floor"}


def test_load_ground_truth_errors(tmp_path):
    from kinfu_cli.core.errors import RecordingError
    from kinfu_cli.sim.scenario import load_ground_truth

    with pytest.raises(RecordingError, match="no changes.json"):
        load_ground_truth(tmp_path)
    (tmp_path / "changes.json").write_text("{}")
    with pytest.raises(RecordingError, match="not a kinfu synth changes.json"):
        load_ground_truth(tmp_path)


def test_raw_images_and_30_hz_hand(tmp_path):
    from kinfu_cli.io.frames import iter_frames
    from kinfu_cli.io.hand import load_hand_trajectory
    from kinfu_cli.io.polhemus import read_polhemus
    from kinfu_cli.io.recording import open_recording

    out = tmp_path / "raw"
    res = CliRunner().invoke(cli, ["synth", "-o", str(out), "--formats", "bag", "--depth-format", "raw",
                                   "--color-format", "raw", "--hand-rate", "30", "--scenario", "place",
                                   "--width", "32", "--height", "24", "--frames", "3", "--seed", "4", "-q"])
    assert res.exit_code == 0, res.output
    assert not (out / "recording.mcap").exists() and (out / "recording.bag").exists()
    sc = make_scenario(4, "place", width=32, height=24, frames=3, hand_rate_hz=30)
    with open_recording(out / "recording.bag") as rec:
        assert rec.topics["/camera/depth/image_raw"].count == 3
        frames = list(iter_frames(rec))
    for f in frames:
        ref = sc.render(f.index)
        assert np.array_equal(f.color, ref.color)                        # rgb8 is lossless
        assert np.array_equal(np.round(f.depth * 1000).astype(np.uint16), depth_to_mm(ref.depth))
    hand = load_hand_trajectory(out / "recording.bag")
    assert np.allclose(np.diff(hand.t), 1 / 30, atol=1e-6)
    traj = read_polhemus(out / "ground_truth" / "hand.traj")           # the .traj file is always 100 Hz
    assert abs(len(traj) - (sc.hand.duration * 100 + 1)) <= 1


def test_ground_truth_names_the_topics_written(tmp_path):
    from kinfu_cli.io.recording import open_recording
    from kinfu_cli.sim.scenario import load_ground_truth

    for depth, color in (("png", "jpeg"), ("raw", "raw")):
        out = tmp_path / depth
        res = CliRunner().invoke(cli, ["synth", "-o", str(out), "--formats", "mcap", "--depth-format", depth,
                                       "--color-format", color, "--width", "16", "--height", "12", "--frames", "2",
                                       "-q"])
        assert res.exit_code == 0, res.output
        topics = load_ground_truth(out).info["topics"]
        with open_recording(out / "recording.mcap") as rec:
            assert set(rec.topics) == set(topics.values())


def test_rendering_the_ground_truth_mesh_matches_the_scene(sample_dir):
    """What `kinfu eval nbv` does: render scene_after.ply (a plain mesh) instead of the Scene object."""
    from kinfu_cli.sim.scenario import load_ground_truth
    from kinfu_cli.sim.sensor import DepthSensor

    gt = load_ground_truth(sample_dir)
    sc = make_scenario(gt.info["seed"], gt.info["scenario"], width=80, height=60, frames=gt.info["frames"]["count"])
    sensor = DepthSensor(sc.K, 80, 60, noise=False)
    T = gt.poses[-1]
    d_mesh, c_mesh = sensor.render(gt.mesh("after"), T)
    d_scene, c_scene = DepthSensor(sc.K, 80, 60, noise=False).render(sc.scene_after, T)
    both = (d_mesh > 0) & (d_scene > 0)
    assert both.mean() > 0.95 and np.array_equal(d_mesh > 0, d_scene > 0)
    assert np.abs(d_mesh[both] - d_scene[both]).max() < 1e-4
    # vertex colours give the objects' colours (the table's wood texture is procedural, so compare objects only)
    obj = sensor.render_frame(sc.scene_after, T).labels >= 3
    assert obj.sum() > 20
    assert np.abs(c_mesh[obj].astype(int) - c_scene[obj].astype(int)).mean() < 3
