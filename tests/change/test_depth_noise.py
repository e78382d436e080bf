"""The depth-noise margin: a far surface that two fusions place a few centimetres apart (Kinect-like noise at
3 m) is no change, a real removal near the cameras still is; the camera positions come from the trajectory.tum
beside each volume, and without them the fixed margin alone applies (as before)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from kinfu_cli.change.diff import ChangeParams, diff_grids, diff_volumes
from kinfu_cli.change.noise import depth_sigma, noise_margins
from kinfu_cli.change.regions import empty_all_around, empty_within
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.io.tum import write_tum

VS = 0.01
CAMERA = np.array([0.2, 0.2, 0.0])  # looking along +z
OBJECT = (10, 16, 10, 16, 100, 106)  # a 6 cm cube 1 m from the camera (voxel ranges x, y, z)


def _labels(wall_k: int, with_object: bool) -> np.ndarray:
    """Free space, a wall whose front face is at voxel wall_k (3 voxels occupied behind it, unknown beyond) and
    optionally the cube (its face band occupied, the space behind it unknown)."""
    lab = np.full((40, 40, 350), -1, dtype=np.int8)
    lab[:, :, wall_k:wall_k + 3] = 1
    lab[:, :, wall_k + 3:] = 0
    if with_object:
        x0, x1, y0, y1, z0, z1 = OBJECT
        lab[x0:x1, y0:y1, z0:z0 + 3] = 1
        lab[x0:x1, y0:y1, z0 + 3:wall_k] = 0  # its shadow
    return lab


def _pair(tmp_path, trajectories: bool):
    paths = []
    for name, wall_k, obj in (("before", 300, True), ("after", 303, False)):  # the wall 3 cm apart at 3 m
        folder = tmp_path / name
        folder.mkdir()
        save_ternary(folder / "ternary.npz", TernaryGrid(_labels(wall_k, obj), np.zeros(3), VS, "world"))
        if trajectories:
            poses = np.tile(np.eye(4), (3, 1, 1))
            poses[:, :3, 3] = CAMERA + np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]])
            write_tum(folder / "trajectory.tum", np.arange(3) * 10**8, poses)
        paths.append(folder / "ternary.npz")
    return paths


def test_far_surface_noise_is_no_change_but_a_near_removal_is(tmp_path):
    before, after = _pair(tmp_path, trajectories=True)
    r = diff_volumes(before, after)
    doc = r.to_json()
    assert [x.kind for x in r.regions] == ["removed"], [(x.kind, len(x.points), x.centroid) for x in r.regions]
    centre = (np.array(OBJECT[::2]) + np.array(OBJECT[1::2])) / 2 * VS
    assert abs(r.regions[0].centroid[0] - centre[0]) < 0.02 and abs(r.regions[0].centroid[2] - 1.0) < 0.03
    assert doc["parameters"]["depth_noise"]["cameras"] == {"before": 3, "after": 3}
    assert doc["counts"]["within_depth_noise"]["removed"] > 1000  # the wall's slab, dropped as noise
    # the same files with the noise margin off, or without trajectories: the wall's 3 cm shift is a change
    assert len(diff_volumes(before, after, ChangeParams(noise_sigmas=0)).regions) == 2
    bare = tmp_path / "bare"
    for name in ("before", "after"):
        shutil.copytree(tmp_path / name, bare / name, ignore=shutil.ignore_patterns("trajectory.tum"))
    r0 = diff_volumes(bare / "before" / "ternary.npz", bare / "after" / "ternary.npz")
    assert len(r0.regions) == 2 and r0.to_json()["parameters"]["depth_noise"] is None


def test_one_trajectory_stands_for_both(tmp_path):
    before, after = _pair(tmp_path, trajectories=True)
    (after.parent / "trajectory.tum").unlink()
    g = [TernaryGrid(_labels(k, o), np.zeros(3), VS, "world") for k, o in ((300, True), (303, False))]
    r = diff_grids(*g, cameras=(np.array([CAMERA]), None))
    assert [x.kind for x in r.regions] == ["removed"]
    assert len(diff_volumes(before, after).regions) == 1


def test_noise_margin_grows_with_distance_as_the_kinect_model():
    assert depth_sigma(np.array([0.4]))[0] == pytest.approx(0.0012)
    assert depth_sigma(np.array([3.0]))[0] == pytest.approx(0.0012 + 0.0019 * 2.6 ** 2)
    pts = np.array([[0, 0, 0.8], [0, 0, 2.0], [0, 0, 3.0]])
    m = noise_margins(pts, np.zeros((1, 3)), np.zeros((1, 3)), 2.0, 0.005)
    assert m[0] == 1 and m[0] < m[1] < m[2] and m[2] == 8  # 2 sqrt(2) 14.0 mm / 5 mm -> 8 voxels


def test_empty_within_is_empty_all_around_with_each_voxels_own_margin():
    rng = np.random.default_rng(3)
    lab = np.where(rng.random((30, 30, 30)) < 0.003, 1, -1).astype(np.int8)
    idx = rng.integers(0, 30, (120, 3))
    margins = rng.integers(0, 5, 120)
    want = np.array([empty_all_around(lab, i[None], int(m))[0] for i, m in zip(idx, margins)])
    assert want.any() and not want.all()
    assert np.array_equal(empty_within(lab, idx, margins), want)
    one = empty_all_around(lab, idx, 1)
    assert np.array_equal(empty_within(lab, idx[one], np.maximum(margins[one], 1), start=1), want[one])


def test_bad_noise_sigmas_is_a_one_line_error_naming_the_option(tmp_path):
    from click.testing import CliRunner

    from kinfu_cli.cli import cli

    before, after = _pair(tmp_path, trajectories=True)
    res = CliRunner().invoke(cli, ["diff", str(before), str(after), "-o", str(tmp_path / "d"), "--noise-sigmas", "-1"])
    assert res.exit_code == 2 and "--noise-sigmas" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "d").exists()
