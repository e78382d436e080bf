"""`kinfu import`: real RGB-D folders into recordings give back the exact depth, intrinsics and poses."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation
from conftest import one_line_error

from kinfu_cli.core.ownership import MANIFEST
from kinfu_cli.cli import cli
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.rgbd_folders import nearest_rotation
from kinfu_cli.io.roles import detect_roles


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _check_folder(rec_path, folder, numbers, color_ext, rate=30.0):
    """Every frame of the recording equals the folder's files: depth bit-exact, pose, K, colour."""
    K = np.loadtxt(next(p for p in (folder / "camera-intrinsics.txt", folder / "intrinsics.K.txt") if p.exists()))
    with open_recording(rec_path) as rec:
        roles = detect_roles(rec)
        assert (roles.depth_topic, roles.info_topic, roles.camera_frame, roles.world_frame) == (
            "/camera/depth/image_raw", "/camera/depth/camera_info", "camera_optical", "world")
        stats = FrameStats()
        frames = list(iter_frames(rec, roles, tolerance_s=0.001, stats=stats))
    assert stats.used == len(numbers) and stats.dropped_total == 0 and stats.without_color == 0
    for f, n in zip(frames, numbers):
        stem = folder / f"frame-{n:06d}"
        raw = cv2.imread(f"{stem}.depth.png", cv2.IMREAD_UNCHANGED)
        expect = raw.astype(np.float32) * np.float32(0.001)
        expect[raw == 65535] = 0.0  # 7-Scenes: 65535 = no measurement
        np.testing.assert_array_equal(f.depth, expect)
        assert f.stamp_ns == round(n / rate * 1e9)
        T = np.loadtxt(f"{stem}.pose.txt")
        np.testing.assert_array_equal(f.T_world_camera[:3, 3], T[:3, 3])  # translation bit-exact
        np.testing.assert_allclose(f.T_world_camera[:3, :3], nearest_rotation(T[:3, :3]), atol=1e-12)
        np.testing.assert_allclose(f.T_world_camera[:3, :3], T[:3, :3], atol=2e-4)  # data set's own rounding
        np.testing.assert_array_equal(f.K, K)
        color = cv2.cvtColor(cv2.imread(f"{stem}.color.{color_ext}"), cv2.COLOR_BGR2RGB)
        np.testing.assert_array_equal(f.color, color)  # the data set's own bytes, decoded the same way
    return frames


def test_import_7scenes_full_into_mcap(tmp_path, shared_data):
    folder = shared_data("rgbd-7scenes-redkitchen")
    out = tmp_path / "kitchen.mcap"
    res = run("import", folder, "-o", out, "--json", "-q")
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert s["frames"] == 60 and s["tf_samples"] == 60 and s["layout"] == "7scenes"
    assert s["K"] == [[585.0, 0.0, 320.0], [0.0, 585.0, 240.0], [0.0, 0.0, 1.0]]
    assert 0 < s["max_rotation_orthonormality_error"] < 2e-4
    assert [p.name for p in tmp_path.iterdir() if p.name != MANIFEST] == ["kitchen.mcap"]
    frames = _check_folder(out, folder, list(range(60)), "jpg")
    assert frames[-1].stamp_ns == round(59 / 30 * 1e9)


@pytest.mark.parametrize("name", ["box.mcap", "box.bag", "box_ros2"])
def test_import_tabletop_subset(tmp_path, shared_data, name):
    folder = shared_data("rgbd-tabletop-box")
    out = tmp_path / name
    res = run("import", folder, "-o", out, "--frames", "0:50:10" if name == "box.mcap" else "3", "-q")
    assert res.exit_code == 0, res.output
    assert "wrote" in res.output and "7scenes layout" in res.output
    numbers = [15 + 2 * i for i in (range(0, 50, 10) if name == "box.mcap" else range(3))]
    frames = _check_folder(out, folder, numbers, "png")
    np.testing.assert_allclose(frames[0].T_world_camera, np.eye(4), atol=1e-12)  # poses relative to frame 15


def _tum_folder(tmp_path):
    """A small TUM-layout folder: depth in 1/5000 m, rgb stamps offset, ground truth at 100 Hz."""
    d = tmp_path / "rgbd_dataset_freiburg1_xyz"
    (d / "depth").mkdir(parents=True)
    (d / "rgb").mkdir()
    rng = np.random.default_rng(3)
    depth_lines, rgb_lines, gt_lines = ["# depth maps"], ["# color images"], ["# timestamp tx ty tz qx qy qz qw"]
    raws = []
    for i in range(4):
        t = 1305031102.0 + i / 30
        raw = rng.integers(0, 30000, (12, 16)).astype(np.uint16)
        raws.append(raw)
        cv2.imwrite(str(d / "depth" / f"{t:.6f}.png"), raw)
        cv2.imwrite(str(d / "rgb" / f"{t + 0.004:.6f}.png"), np.full((12, 16, 3), 40 * i, np.uint8))
        depth_lines.append(f"{t:.6f} depth/{t:.6f}.png")
        rgb_lines.append(f"{t + 0.004:.6f} rgb/{t + 0.004:.6f}.png")
    for k in range(-5, 20):
        t = 1305031102.0 + k / 100
        q = Rotation.from_rotvec([0, 0, 0.3 * k / 100]).as_quat()
        gt_lines.append(f"{t:.4f} {0.1 * k / 100:.6f} 0.5 1.0 {q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}")
    (d / "depth.txt").write_text("\n".join(depth_lines) + "\n")
    (d / "rgb.txt").write_text("\n".join(rgb_lines) + "\n")
    (d / "groundtruth.txt").write_text("\n".join(gt_lines) + "\n")
    return d, raws


def test_import_tum_layout(tmp_path):
    folder, raws = _tum_folder(tmp_path)
    out = tmp_path / "tum.bag"
    res = run("import", folder, "-o", out, "--json", "-q")
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert s["layout"] == "tum" and s["frames"] == 4 and s["K_source"] == "TUM freiburg1 calibration"
    assert s["K"][0][0] == 517.3
    with open_recording(out) as rec:
        frames = list(iter_frames(rec, tolerance_s=0.01))
    assert len(frames) == 4
    for i, f in enumerate(frames):
        mm = np.rint(raws[i] / 5.0)
        np.testing.assert_array_equal(f.depth, (mm.astype(np.float32) * np.float32(0.001)))
        t = (f.stamp_ns - 1305031102 * 10**9) * 1e-9
        np.testing.assert_allclose(f.T_world_camera[:3, 3], [0.1 * t, 0.5, 1.0], atol=1e-6)
        np.testing.assert_allclose(Rotation.from_matrix(f.T_world_camera[:3, :3]).as_rotvec(), [0, 0, 0.3 * t],
                                   atol=1e-6)
        assert f.color[0, 0, 0] == 40 * i


def test_import_bad_input(tmp_path, shared_data):
    one_line_error(run("import", tmp_path / "nope", "-o", tmp_path / "x.mcap"), "nope", "not a folder")
    empty = tmp_path / "empty"
    empty.mkdir()
    one_line_error(run("import", empty, "-o", tmp_path / "x.mcap"), "empty", "no frame-N.depth.png")
    src = shared_data("rgbd-tabletop-box")
    bad = tmp_path / "bad"
    bad.mkdir()
    for n in (15, 17, 19):
        for ext in ("depth.png", "pose.txt"):
            shutil.copy(src / f"frame-{n:06d}.{ext}", bad / f"frame-{n:06d}.{ext}")
    one_line_error(run("import", bad, "-o", tmp_path / "x.mcap"), "bad", "intrinsics")
    one_line_error(run("import", bad, "-o", tmp_path / "x.mcap", "--intrinsics", "600,600"), "--intrinsics")
    one_line_error(run("import", bad, "-o", tmp_path / "x.mcap", "--intrinsics", "600,600,320,240",
                       "--frames", "9:"), "--frames", "selects none")
    # a broken depth image in the middle: error naming it, and no recording left behind
    (bad / "frame-000017.depth.png").write_bytes(b"not a png")
    for out in ("x.mcap", "x.bag", "x_ros2"):
        one_line_error(run("import", bad, "-o", tmp_path / out, "--intrinsics", "600,600,320,240"),
                       "frame-000017.depth.png", "cannot read the depth image")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad", "empty"]


def test_3dmatch_scene_with_sequence_folders(tmp_path, shared_data):
    """3DMatch keeps camera-intrinsics.txt at the scene root and frames in seq-XX/ folders."""
    src = shared_data("rgbd-7scenes-redkitchen")
    scene = tmp_path / "scene"
    seq = scene / "seq-01"
    seq.mkdir(parents=True)
    shutil.copy(src / "camera-intrinsics.txt", scene / "camera-intrinsics.txt")
    for n in (0, 1):
        for ext in ("depth.png", "color.jpg", "pose.txt"):
            shutil.copy(src / f"frame-{n:06d}.{ext}", seq / f"frame-{n:06d}.{ext}")
    one_line_error(run("import", scene, "-o", tmp_path / "x.mcap"), "sequence folders (seq-01)", "seq-01")
    res = run("import", seq, "-o", tmp_path / "seq.mcap", "-q")
    assert res.exit_code == 0, res.output
    _check_folder(tmp_path / "seq.mcap", src, [0, 1], "jpg")
