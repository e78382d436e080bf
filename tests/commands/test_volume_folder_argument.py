"""segment, diff and nbv take a `kinfu fuse` output folder where they take its volume.npz (as grasp takes a
segment folder). Before: `kinfu segment FUSE_DIR` was refused with click's usage block ("is a directory"), and nbv
said the folder was no volume file."""

from __future__ import annotations

import json

from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import primitive_tabletop_scene
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics


def _fuse_folder(path):
    scene = primitive_tabletop_scene(3)
    K = kinect_v1_intrinsics(160, 120)
    sensor = DepthSensor(K, 160, 120, noise=False, seed=3)
    vol = TernaryVolume(size=(1.28, 0.8, 0.4), voxel_size=0.01, origin=(-0.64, -0.4, 0.6), truncation=0.04,
                        min_depth=0.2, max_depth=2.0)
    for T in orbit_poses(3, radius=0.85, height=1.3, target=(0, 0, 0.75)):
        depth, colour = sensor.render(scene, T)
        vol.integrate(depth, K, T, colour)
    path.mkdir()
    vol.save(path / "volume.npz")
    return path


def test_a_fuse_folder_stands_for_its_volume(tmp_path):
    fused = _fuse_folder(tmp_path / "fuse")
    run = CliRunner().invoke
    by_file = run(cli, ["segment", str(fused / "volume.npz"), "-o", str(tmp_path / "a"), "--no-superquadrics",
                        "--quiet"])
    by_folder = run(cli, ["segment", str(fused), "-o", str(tmp_path / "b"), "--no-superquadrics", "--quiet"])
    assert by_file.exit_code == 0 and by_folder.exit_code == 0, by_folder.output
    a, b = (json.loads((tmp_path / n / "segments.json").read_text()) for n in "ab")
    assert len(a["segments"]) >= 3 and a["segments"] == b["segments"]
    res = run(cli, ["diff", str(fused), str(fused / "volume.npz"), "-o", str(tmp_path / "d"), "--json", "--quiet"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["regions"] == []  # a volume against itself: nothing changed


def test_a_folder_without_a_volume_is_one_line(tmp_path):
    (tmp_path / "empty").mkdir()
    for args in (["segment", str(tmp_path / "empty"), "-o", str(tmp_path / "s")],
                 ["nbv", str(tmp_path / "empty"), "--mode", "objects"]):
        res = CliRunner().invoke(cli, args)
        line = one_line_error(res)
        assert "a folder without volume.npz or ternary.npz" in line and str(tmp_path / "empty") in line
