"""`kinfu import`: real RGB-D folders into recordings give back the exact depth, intrinsics and poses."""

from __future__ import annotations

import json
import shutil
import warnings

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
    res = run("import", folder, "-o", out, "--frames", "0:50:10" if name == "box.mcap" else "3")
    assert res.exit_code == 0, res.output
    assert "wrote" in res.output and "7scenes layout" in res.output
    numbers = [15 + 2 * i for i in (range(0, 50, 10) if name == "box.mcap" else range(3))]
    frames = _check_folder(out, folder, numbers, "png")
    np.testing.assert_allclose(frames[0].T_world_camera, np.eye(4), atol=1e-12)  # poses relative to frame 15


def _tum_folder(tmp_path, name="rgbd_dataset_freiburg1_xyz", shape=(480, 640), gt_shift_s=0.0):
    """A small TUM-layout folder of 4 frames: depth in 1/5000 m, rgb stamps offset, ground truth at 100 Hz
    (shifted by gt_shift_s). No intrinsics file: TUM's calibrations, which are for 640x480, apply."""
    d = tmp_path / name
    (d / "depth").mkdir(parents=True)
    (d / "rgb").mkdir()
    rng = np.random.default_rng(3)
    depth_lines, rgb_lines, gt_lines = ["# depth maps"], ["# color images"], ["# timestamp tx ty tz qx qy qz qw"]
    raws = []
    for i in range(4):
        t = 1305031102.0 + i / 30
        raw = rng.integers(0, 30000, shape).astype(np.uint16)
        raws.append(raw)
        cv2.imwrite(str(d / "depth" / f"{t:.6f}.png"), raw)
        cv2.imwrite(str(d / "rgb" / f"{t + 0.004:.6f}.png"), np.full((*shape, 3), 40 * i, np.uint8))
        depth_lines.append(f"{t:.6f} depth/{t:.6f}.png")
        rgb_lines.append(f"{t + 0.004:.6f} rgb/{t + 0.004:.6f}.png")
    for k in range(-5, 20):
        t = 1305031102.0 + k / 100 + gt_shift_s
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
    s = json.loads(res.stdout)
    assert s["layout"] == "tum" and s["frames"] == 4 and s["K_source"] == "TUM freiburg1 calibration"
    assert s["K"][0][0] == 517.3 and s["warnings"] == []
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


def _warnings(res):
    return [l[len("kinfu: warning: "):] for l in res.stderr.splitlines() if l.startswith("kinfu: warning: ")]


@pytest.mark.parametrize("text", ["", "# timestamp tx ty tz qx qy qz qw\n"])
def test_tum_groundtruth_without_samples_is_a_warning_not_a_traceback(tmp_path, text):
    """Like a folder without groundtruth.txt (no poses), but the file that says nothing is named."""
    folder, _ = _tum_folder(tmp_path)
    (folder / "groundtruth.txt").write_text(text)
    res = run("import", folder, "-o", tmp_path / "x.mcap", "--json", "-q")
    assert res.exit_code == 0 and "Traceback" not in res.output, res.output
    s = json.loads(res.stdout)
    assert s["tf_samples"] == 0 and s["frames"] == 4
    [w] = _warnings(res)
    assert "groundtruth.txt" in w and "no camera poses" in w and w == s["warnings"][0]


def test_tum_groundtruth_outside_the_depth_frames_is_a_warning(tmp_path):
    folder, _ = _tum_folder(tmp_path, gt_shift_s=100.0)
    res = run("import", folder, "-o", tmp_path / "x.mcap")
    assert res.exit_code == 0, res.output
    assert "0 TF samples" in res.stdout
    [w] = _warnings(res)
    assert "groundtruth.txt" in w and "no ground-truth pose within the depth frames' time span" in w


def test_tum_default_intrinsics_only_for_640x480(tmp_path):
    """TUM's default K (and its freiburg calibrations) are for 640x480: other sizes need --intrinsics, and at
    640x480 the guessed default is said."""
    small, _ = _tum_folder(tmp_path, name="tum_small", shape=(48, 64))
    one_line_error(run("import", small, "-o", tmp_path / "x.mcap", "-q"), "--intrinsics", "tum_small", "640x480",
                   "64x48")
    named, _ = _tum_folder(tmp_path, name="rgbd_dataset_freiburg2_small", shape=(48, 64))
    one_line_error(run("import", named, "-o", tmp_path / "x.mcap", "-q"), "--intrinsics", "freiburg2", "64x48")
    res = run("import", small, "-o", tmp_path / "x.mcap", "-q", "--intrinsics", "60,60,31.5,23.5")
    assert res.exit_code == 0 and _warnings(res) == [], res.output
    vga, _ = _tum_folder(tmp_path, name="tum_vga")
    res = run("import", vga, "-o", tmp_path / "vga.mcap", "--json", "-q")
    assert res.exit_code == 0, res.output
    s = json.loads(res.stdout)
    assert s["K"] == [[525.0, 0.0, 319.5], [0.0, 525.0, 239.5], [0.0, 0.0, 1.0]]
    [w] = _warnings(res)
    assert "tum_vga" in w and "TUM default" in w and w == s["warnings"][0]


def _7scenes_folder(d, n=6, poses=None):
    """n frames of 8x6 depth with identity-rotation poses moving along x; poses: {frame: text of its pose file,
    or None for no file}."""
    d.mkdir(parents=True)
    (d / "camera-intrinsics.txt").write_text("6 0 3.5\n0 6 2.5\n0 0 1\n")
    for i in range(n):
        cv2.imwrite(str(d / f"frame-{i:06d}.depth.png"), np.full((6, 8), 1000 + i, np.uint16))
        T = np.eye(4)
        T[0, 3] = 0.1 * i
        text = (poses or {}).get(i, "\n".join(" ".join(f"{v:g}" for v in row) for row in T))
        if text is not None:
            (d / f"frame-{i:06d}.pose.txt").write_text(text)
    return d


@pytest.mark.parametrize("name, path, text", [("pose_empty", "frame-000002.pose.txt", ""),
                                             ("pose_blank", "frame-000002.pose.txt", "  \n\n"),
                                             ("intr_empty", "camera-intrinsics.txt", "")])
def test_empty_matrix_file_gives_the_error_without_numpy_warning(tmp_path, name, path, text):
    folder = _7scenes_folder(tmp_path / name)
    (folder / path).write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = run("import", folder, "-o", tmp_path / "x.mcap", "-q")
    one_line_error(res, path, "0 numbers")
    assert [str(w.message) for w in caught] == []


def test_two_intrinsics_files_must_agree(tmp_path):
    folder = _7scenes_folder(tmp_path / "both")
    (folder / "intrinsics.K.txt").write_text("6.0 0 3.5\n0 6.0 2.5\n0 0 1.0\n")  # the same K
    res = run("import", folder, "-o", tmp_path / "x.mcap", "--json", "-q")
    assert res.exit_code == 0 and json.loads(res.stdout)["K_source"] == "camera-intrinsics.txt", res.output
    (folder / "intrinsics.K.txt").write_text("9 0 3.5\n0 9 2.5\n0 0 1\n")
    one_line_error(run("import", folder, "-o", tmp_path / "y.mcap", "-q"), "camera-intrinsics.txt",
                   "intrinsics.K.txt", "disagree")


def test_7scenes_frames_without_pose_are_left_out(tmp_path):
    """A frame whose pose is -inf, NaN or missing among posed frames is not written (fusion would interpolate
    a pose for it); the output counts the frames left out and says why."""
    inf = "\n".join(["-inf -inf -inf -inf"] * 4)
    nan = "\n".join(["nan nan nan nan"] * 4)
    folder = _7scenes_folder(tmp_path / "seq", poses={1: inf, 2: nan, 4: None})
    out = tmp_path / "x.mcap"
    res = run("import", folder, "-o", out, "--json", "-q")
    assert res.exit_code == 0, res.output
    s = json.loads(res.stdout)
    assert (s["frames"], s["frames_in_folder"], s["frames_left_out"], s["tf_samples"]) == (3, 6, 3, 3)
    [w] = _warnings(res)
    assert "3 of 6 frames left out" in w and "not finite: 2" in w and "missing: 1" in w
    assert "frame-000001" in w and "frame-000004" in w
    with open_recording(out) as rec:
        stats = FrameStats()
        frames = list(iter_frames(rec, tolerance_s=0.001, stats=stats))
    assert [round(f.stamp_ns * 30e-9) for f in frames] == [0, 3, 5] and stats.dropped_total == 0
    for f in frames:
        n = round(f.stamp_ns * 30e-9)
        np.testing.assert_allclose(f.T_world_camera[0, 3], 0.1 * n, atol=1e-12)  # its own pose, not interpolated
        assert f.depth[0, 0] == np.float32((1000 + n) * 0.001)
    res = run("import", folder, "-o", tmp_path / "text.mcap")
    assert "3 of 6 frames (7scenes layout, 3 left out without a pose)" in res.stdout


def test_7scenes_frames_all_without_pose_are_kept(tmp_path):
    """No usable pose at all: every frame is written without TF (fusion tracks them), with a warning when pose
    files were there but not finite; a folder without pose files is plain."""
    inf = "\n".join(["-inf -inf -inf -inf"] * 4)
    folder = _7scenes_folder(tmp_path / "inf", n=3, poses={0: inf, 1: inf, 2: inf})
    res = run("import", folder, "-o", tmp_path / "x.mcap", "--json", "-q")
    assert res.exit_code == 0, res.output
    s = json.loads(res.stdout)
    assert (s["frames"], s["frames_left_out"], s["tf_samples"]) == (3, 0, 0)
    [w] = _warnings(res)
    assert "none of the 3 frames has a usable pose" in w and "not finite: 3" in w
    bare = _7scenes_folder(tmp_path / "bare", n=3, poses={0: None, 1: None, 2: None})
    res = run("import", bare, "-o", tmp_path / "y.mcap")
    assert res.exit_code == 0 and _warnings(res) == [] and "3 of 3 frames" in res.stdout, res.output
