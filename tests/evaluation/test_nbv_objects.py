"""`kinfu eval nbv --strategy objects,standard`: POI-free exploration, object-driven vs standard planning."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation.nbv_loop import LoopConfig, near_object_voxels, run_loop
from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.nbv.objects import not_attempted

SMALL = dict(width=160, height=120, score_width=80)


@pytest.fixture(scope="module")
def explore_doc(sample_dir):
    cfg = LoopConfig(strategies=("objects", "standard"), views=3, **SMALL)
    return run_loop(sample_dir / "ground_truth", cfg)


@pytest.mark.slow
def test_object_driven_views_cast_3_9x_fewer_candidates_for_the_same_reduction(explore_doc):
    doc = explore_doc
    near = doc["near_objects"]
    assert len(near["spheres"]) == 4 and near["voxels"] > 100_000
    obj, std = doc["strategies"]["objects"], doc["strategies"]["standard"]
    for r in (obj, std):
        u = r["unknown_near"]
        assert len(u) == 4 and u[0] == near["unknown_initial"]
        assert all(b <= a for a, b in zip(u, u[1:])), u
        # no view is taken twice (the planner skips attempted viewpoints)
        p = np.array(r["poses"])
        assert all(not_attempted(p[i + 1:], p[i:i + 1]).all() for i in range(len(p) - 1))
    # the object strategy does not stall: 3 views reveal most of what is unknown near the objects (79.7k -> 20.4k
    # since table-level fragments go to the support before small segments merge; 16.9k before, when a fragment
    # of the table's edge could join the object beside it and move its contours)
    assert obj["unknown_near"][-1] < 0.3 * obj["unknown_near"][0]
    assert obj["unknown_near"][-1] <= 1.1 * std["unknown_near"][-1]
    eq = doc["equal_reduction"]
    # with the thesis' W_th = 5 (unknown = seen fewer than 5 times, for planners and measure alike) the standard
    # plan stalls at a third of the reduction (sample: 79.7k -> 51.4k unknown voxels near the objects in 3 views)
    # where the object plan reaches 79 % (-> 16.9k); the object plan gets to the standard's level in one view
    assert eq["reduction_fraction"] > 0.3
    assert obj["unknown_near"][-1] < 0.5 * std["unknown_near"][-1]
    assert eq["cast_ratio"] >= 3.9, eq
    assert doc["cast_ratio_standard_over_objects"] >= 3.9
    # (time_ratio_standard_over_objects is a wall-time ratio: not asserted, it fell to 0.85 at load 15; the cast
    # ratio above is the work measure)
    # every object view goes to a segment's sphere, the standard plan has none
    assert all(s is not None for s in obj["segments"]) and all(s is None for s in std["segments"])


def test_not_attempted_skips_views_within_a_few_cm_and_degrees():
    T = np.eye(4)
    near = T.copy()
    near[:3, 3] = [0.03, 0, 0]
    rolled = T.copy()
    rolled[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # same optical axis, other roll
    far = T.copy()
    far[:3, 3] = [0.2, 0, 0]
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    turned = T.copy()
    turned[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    keep = not_attempted(np.stack([T, near, rolled, far, turned]), T[None])
    assert keep.tolist() == [False, False, False, True, True]
    assert not_attempted(np.stack([T, near]), None).all()


def test_near_object_voxels_are_inside_the_enlarged_spheres_above_the_table():
    g = TernaryGrid(np.zeros((50, 50, 50), np.int8), origin=np.zeros(3), voxel_size=0.02)
    spheres = np.array([[0.5, 0.5, 0.5, 0.1], [0.52, 0.5, 0.5, 0.05]])
    idx = near_object_voxels(g, spheres, 0.1, table_z=0.45)
    cen = g.centers(idx)
    assert len(np.unique(idx, axis=0)) == len(idx)
    assert np.all(np.linalg.norm(cen - [0.5, 0.5, 0.5], axis=1) <= 0.2 + 1e-9) and np.all(cen[:, 2] > 0.45)
    # a 0.2 m ball of 2 cm voxels, cut at z = 0.45 (0.05 below its centre): about 2/3 of 4/3 pi 0.2^3 / 0.02^3
    assert 0.6 * 4189 < len(idx) < 0.75 * 4189


def test_cli_eval_nbv_objects_table_and_json(sample_dir, tmp_path):
    out = tmp_path / "explore.json"
    args = ["eval", "nbv", str(sample_dir), "--strategy", "objects", "--views", "1", "--width", "160",
            "--height", "120", "--score-width", "48", "--no-noise"]
    res = CliRunner().invoke(cli, args + ["-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "unknown voxels near objects" in res.output and "candidate views ray-cast" in res.output
    doc = json.loads(out.read_text())
    r = doc["strategies"]["objects"]
    assert doc["kind"] == "exploration" and len(r["unknown_near"]) == 2
    assert r["unknown_near"][1] < 0.85 * r["unknown_near"][0]  # W_th = 5 unknown: 71.8k -> 58.0k at 48 px
    assert 0 < r["candidates_cast_total"] <= 2000 and r["segments"][0] is not None
    res = CliRunner().invoke(cli, args + ["--json", "--quiet"])
    assert res.exit_code == 0 and json.loads(res.output)["strategies"]["objects"]["unknown_near"] == r["unknown_near"]


@pytest.mark.parametrize("args, expect", [
    (["--strategy", "objects,poi"], "--strategy"),
    (["--strategy", "objects", "--scan-frames", "0"], "--scan-frames"),
    (["--strategy", "standard", "--score-width", "2"], "--score-width"),
])
def test_cli_eval_nbv_objects_bad_options(sample_dir, args, expect, tmp_path):
    out = tmp_path / "x.json"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(sample_dir), "--quiet", "-o", str(out)] + args)
    assert res.exit_code == 2 and "kinfu: error:" in res.output and expect in res.output
    assert not out.exists()


def test_cli_eval_nbv_objects_on_a_bare_mesh_is_an_error(sample_dir, tmp_path):
    mesh = sample_dir / "ground_truth" / "scene_after.ply"
    out = tmp_path / "m.json"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(mesh), "--poi", "0.3", "0", "0.8", "--strategy", "objects",
                                   "--width", "80", "--height", "60", "--quiet", "-o", str(out)])
    assert res.exit_code == 2 and "true objects" in res.output and not out.exists()
