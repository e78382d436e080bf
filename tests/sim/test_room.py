"""`kinfu synth --scene room`: a room-scale sequence that fuse keeps whole (auto size), in z-up and y-down worlds."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import load_ternary
from kinfu_cli.sim.room import ROOM_SIZE, make_room, world_rotation
from kinfu_cli.sim.synth import synthesize

SMALL = ["--frames", "12", "--width", "80", "--height", "60", "--formats", "mcap", "--quiet"]
VOXEL = 0.04


def _run(args):
    res = CliRunner().invoke(cli, args, catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def rooms(tmp_path_factory):
    """{world: (synth folder, fuse folder, report.json)} of the small room fused with no size option."""
    out = {}
    for world in ("z-up", "y-down"):
        base = tmp_path_factory.mktemp(world)
        _run(["synth", "-o", str(base / "rec"), "--scene", "room", "--world", world, *SMALL])
        _run(["fuse", str(base / "rec" / "recording.mcap"), "-o", str(base / "fuse"), "--voxel-size", str(VOXEL),
              "--quiet"])
        out[world] = (base / "rec", base / "fuse", json.loads((base / "fuse" / "report.json").read_text()))
    return out


def test_room_geometry_and_camera_loop():
    room = make_room(0, "z-up", width=40, height=30, frames=9, noise=False)
    lo, hi = room.bounds()
    assert np.allclose(lo[:2], [-ROOM_SIZE[0] / 2 - 0.1, -ROOM_SIZE[1] / 2 - 0.1])
    assert np.allclose(hi, [ROOM_SIZE[0] / 2 + 0.1, ROOM_SIZE[1] / 2 + 0.1, ROOM_SIZE[2]])
    names = {p[0] for p in room.parts}
    assert {"floor", "wall_-x", "wall_+x", "wall_-y", "lintel", "table_top", "sofa_seat", "shelf"} <= names
    eyes = np.array([f.T_room_camera[:3, 3] for f in room.frames])
    assert np.all(np.abs(eyes[:, 2] - 1.5) < 0.1)  # handheld height
    assert np.all(np.abs(eyes[:, 0]) < ROOM_SIZE[0] / 2 - 0.5) and np.all(np.abs(eyes[:, 1]) < ROOM_SIZE[1] / 2 - 0.5)
    # every frame sees the room (the views up at the wall tops also see the open sky: there is no ceiling)
    valid = [np.mean(room.render(i).depth > 0) for i in range(len(room.frames))]
    assert min(valid) > 0.25 and np.mean(valid) > 0.6
    # y-down: the same images, poses and mesh rotated so that up is -y
    ydown = make_room(0, "y-down", width=40, height=30, frames=9, noise=False)
    W = world_rotation("y-down")
    assert np.allclose(ydown.up, [0, -1, 0])
    assert np.allclose(ydown.frames[4].T_world_camera, W @ room.frames[4].T_world_camera)
    assert np.array_equal(ydown.render(4).depth, room.render(4).depth)
    lo_y, hi_y = ydown.bounds()
    assert abs(lo_y[1] + ROOM_SIZE[2]) < 1e-9 and abs(hi_y[1] - 0.05) < 1e-9  # wall tops at y = -2.5, floor slab below


def test_room_options_are_checked(tmp_path):
    with pytest.raises(ConfigError, match="z-up only"):
        synthesize(tmp_path / "t", width=16, height=12, frames=2, formats=("mcap",), world="y-down")
    with pytest.raises(ConfigError, match="tabletop, room"):
        synthesize(tmp_path / "t", scene="kitchen")
    with pytest.raises(ConfigError, match="at least 3"):
        make_room(frames=2)
    assert not (tmp_path / "t").exists()


def test_auto_size_keeps_the_whole_room(rooms):
    rec, fuse, rep = rooms["z-up"]
    gt = json.loads((rec / "ground_truth" / "changes.json").read_text())
    assert gt["world"] == "z-up" and gt["changes"] == []
    assert rep["grid"]["sizing"]["mode"] == "auto"
    assert sum(rep["grid"]["face_contacts"].values()) == 0
    assert not any("grid faces" in w for w in rep["warnings"])
    occ = rep["bounding_box"]["occupied"]
    lo, hi = np.array(occ["min"]), np.array(occ["max"])
    true_lo, true_hi = np.array(gt["room"]["bounds_min"]), np.array(gt["room"]["bounds_max"])
    tol = 3 * VOXEL
    # the walls' inner faces bound the occupied box in x and y; the floor and the wall tops in z
    inner_lo = np.array([-ROOM_SIZE[0] / 2, -ROOM_SIZE[1] / 2, 0.0])
    inner_hi = np.array([ROOM_SIZE[0] / 2, ROOM_SIZE[1] / 2, ROOM_SIZE[2]])
    assert np.all(lo <= inner_lo + tol) and np.all(lo >= true_lo - tol), (lo, true_lo)
    assert np.all(hi >= inner_hi - tol) and np.all(hi <= true_hi + tol), (hi, true_hi)


def test_a_small_grid_warns_that_the_room_goes_on(rooms, tmp_path):
    rec, _, _ = rooms["z-up"]
    res = _run(["fuse", str(rec / "recording.mcap"), "-o", str(tmp_path / "f3"), "--voxel-size", str(VOXEL),
                "--size", "3", "--quiet"])
    rep = json.loads((tmp_path / "f3" / "report.json").read_text())
    touched = {k: v for k, v in rep["grid"]["face_contacts"].items() if v > 0}
    assert len(touched) >= 3 and sum(touched.values()) > 50
    assert any("grid faces" in w for w in rep["warnings"])
    assert "touch the grid faces" in res.output


@pytest.mark.parametrize("world, up", [("z-up", (0, 0, 1)), ("y-down", (0, -1, 0))])
def test_fuse_takes_the_declared_up(rooms, world, up):
    _, _, rep = rooms[world]
    angle = np.degrees(np.arccos(np.clip(np.dot(rep["up"], up), -1, 1)))
    assert angle < 2.0
    assert rep["up_source"] == "recording"


def test_y_down_room_extent_and_support_plane(rooms, tmp_path):
    rec, fuse, rep = rooms["y-down"]
    occ = rep["bounding_box"]["occupied"]
    # up is -y: the floor (y = 0) and the wall tops (y = -2.5) bound the occupied box in y
    tol = 3 * VOXEL
    assert -tol < occ["max"][1] < 0.05 + tol and abs(occ["min"][1] + ROOM_SIZE[2]) < tol  # floor slab 5 cm thick
    assert sum(rep["grid"]["face_contacts"].values()) == 0
    _run(["segment", str(fuse / "volume.npz"), "-o", str(tmp_path / "seg"), "--resolution", "0.05",
          "--seed-resolution", "0.15", "--adjacency-radius", "0.08", "--plane-distance", "0.04",
          "--no-superquadrics", "--quiet"])
    seg = json.loads((tmp_path / "seg" / "segments.json").read_text())
    n, d = np.array(seg["support_plane"][:3]), seg["support_plane"][3]
    assert abs(abs(n[1]) - 1.0) < 0.01  # horizontal in the y-down world
    height = d / n[1]  # the plane y = -d / n_y, its height above the floor (up is -y)
    assert min(abs(height - 0.0), abs(height - 0.75)) < 2 * VOXEL  # the floor or the table top


def test_hint_mode_fuses_views_of_new_territory_at_their_tf_pose(rooms, tmp_path):
    # consecutive room views barely overlap: ICP from the TF pose cannot refine them (it used to lose every frame
    # and fail the run); hint keeps the robot's pose for them, as forced mode would, and says so
    rec, forced, _ = rooms["y-down"]
    out = tmp_path / "hint"
    res = CliRunner().invoke(cli, ["fuse", str(rec / "recording.mcap"), "-o", str(out), "--voxel-size", str(VOXEL),
                                   "--pose", "hint", "--quiet"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    t = report["tracking"]
    assert t["lost"] == 0 and t["tf_fallback"] == len(t["tf_fallback_frames"]) > 0.5 * t["tracked"]
    fell = [f for f in t["frames"] if f["tf_fallback"]]
    assert all(f["given_minus_tracked_m"] == 0 and f["reason"] for f in fell)
    assert any("fused at their TF pose" in w for w in report["warnings"]) and "fused at their TF pose" in res.output
    # the frames ICP did refine sit on their exact TF poses too: the volume is forced mode's
    a = load_ternary(forced / "ternary.npz").labels
    b = load_ternary(out / "ternary.npz").labels
    seen = (a != 0) | (b != 0)
    assert a.shape == b.shape and (a == b)[seen].mean() > 0.99
