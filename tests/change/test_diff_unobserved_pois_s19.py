"""`kinfu diff --pois` leaves unscored a POI inside the common box whose surroundings one volume never observed:
the diff ignores voxels unknown in either volume, so "no change near it" is no miss there. A POI that reaches a
change region stays scored, and one in space both observed stays a false positive."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.change.diff import diff_grids
from kinfu_cli.cli import cli
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.core.pois import Poi, write_pois
from kinfu_cli.evaluation.change_pois import MIN_KNOWN_SHARE, known_shares

VS = 0.01
POIS = [Poi(0, [0.33, 0.13, 0.11], 1.0, 1.0),  # on the removed cube: true positive
        Poi(1, [0.05, 0.35, 0.11], 2.0, 1.0),  # in the corner the after volume never observed: not scored
        Poi(2, [0.13, 0.13, 0.11], 3.0, 1.0),  # in that corner too, but 0.18 m from the region: true positive
        Poi(3, [0.45, 0.40, 0.15], 4.0, 1.0)]  # observed in both, no change near: false positive


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _labels(cubes_x=()) -> np.ndarray:
    """A table (z 5-8) under free space, unknown below it; a hollow 6-voxel cube on it at each x."""
    lab = np.zeros((60, 50, 30), dtype=np.int8)
    lab[:, :, 8:] = -1
    lab[:, :, 5:8] = 1
    for x in cubes_x:
        lab[x:x + 6, 10:16, 8:14] = 1
        lab[x + 2:x + 4, 12:14, 10:12] = 0
    return lab


def _pair(tmp_path, pois=POIS):
    """before: cubes at x 0.02 and 0.30 m; after: the second cube gone, and x < 0.28 m never observed."""
    after = _labels((2,))
    after[:28] = 0
    for name, lab in (("b.npz", _labels((2, 30))), ("a.npz", after)):
        save_ternary(tmp_path / name, TernaryGrid(lab, np.zeros(3), VS, "world"))
    write_pois(tmp_path / "pois.json", pois, "gmm-as", {}, frame="world")
    return tmp_path / "b.npz", tmp_path / "a.npz", tmp_path / "pois.json"


def test_a_poi_where_one_volume_never_looked_is_not_a_false_positive(tmp_path):
    b, a, pois = _pair(tmp_path)
    res = run("diff", b, a, "-o", tmp_path / "d", "--pois", pois)
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "d" / "changes.json").read_text())
    p = doc["pois"]
    assert [r["kind"] for r in doc["regions"]] == ["removed"]
    assert (p["tp"], p["fp"], p["fn"]) == (2, 1, 0)  # the old scoring: fp 2, POI 1 counted wrong
    assert p["precision"] == pytest.approx(2 / 3) and p["recall"] == 1.0
    assert (p["pois"], p["pois_scored"], p["pois_outside_common_box"], p["pois_unobserved"]) == (4, 3, 0, 1)
    assert [x["scored"] for x in p["per_poi"]] == [True, False, True, True]
    assert [x["reason"] for x in p["per_poi"]] == [None, "unobserved", None, None]
    assert p["per_poi"][1]["known_share"] == 0.0 and p["per_poi"][1]["true_positive"] is False
    # POI 2 sees little of the compared space too, but a region is within the match radius: it stays a hit
    assert p["per_poi"][2]["known_share"] < MIN_KNOWN_SHARE and p["per_poi"][2]["true_positive"] is True
    assert p["per_poi"][3]["known_share"] > 0.5 and p["per_poi"][3]["true_positive"] is False
    for key in ("source", "radius", "changes", "f1", "missed_regions"):
        assert key in p
    (line,) = [w for w in res.output.splitlines() if "barely observed" in w]
    assert line.startswith("kinfu: warning: ") and "pois.json: 1 of 4 POIs (id 1) lie where" in line
    assert f"{a} barely observed" in line and str(b) not in line and "under 10 %" in line
    assert "(3 scored)" in res.output
    assert any("barely observed" in w for w in doc["warnings"])


def test_the_warning_names_the_volume_that_never_looked(tmp_path):
    b, a, pois = _pair(tmp_path)
    res = run("diff", a, b, "-o", tmp_path / "d", "--pois", pois, "--json", "--quiet")  # swapped: "added"
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["pois"]["pois_unobserved"] == 1 and (doc["pois"]["tp"], doc["pois"]["fp"]) == (2, 1)
    (warning,) = [w for w in doc["warnings"] if "barely observed" in w]
    assert f"lie where {a} barely observed" in warning


def test_no_poi_in_observed_space_leaves_precision_undefined(tmp_path):
    b, a, pois = _pair(tmp_path, [POIS[1]])
    res = run("diff", b, a, "-o", tmp_path / "d", "--pois", pois, "--json", "--quiet")
    assert res.exit_code == 0, res.output
    p = json.loads(res.stdout)["pois"]
    assert (p["pois_scored"], p["fp"], p["fn"]) == (0, 0, 1)
    assert p["precision"] is None and p["f1"] is None and p["recall"] == 0.0  # was precision 0.0 from fp 1
    assert any("no POI lies where the volumes were compared" in w for w in json.loads(res.stdout)["warnings"])


def test_known_share_counts_voxels_known_in_both_within_the_radius():
    known = np.full((60, 60, 60), -1, dtype=np.int8)
    half = known.copy()
    half[:30] = 0  # x < 0.30 m never observed
    pair = diff_grids(TernaryGrid(known, np.zeros(3), VS), TernaryGrid(half, np.zeros(3), VS)).pair
    xyz = np.array([[0.45, 0.30, 0.30], [0.30, 0.30, 0.30], [0.15, 0.30, 0.30], [0.45, 0.30, 0.0]])
    s = known_shares(pair, xyz, 0.1)
    assert s[0] == pytest.approx([1.0, 1.0, 1.0])
    assert s[1] == pytest.approx([0.5, 1.0, 0.5], abs=0.02)  # the plane x = 0.30 m halves the ball
    assert s[2] == pytest.approx([0.0, 1.0, 0.0])
    assert s[3] == pytest.approx([0.5, 0.5, 0.5], abs=0.02)  # on the box's face: the half outside was not compared
    # a ball wider than MAX_BALL_SIDE voxels is sampled at a stride: the grid's 0.216 m^3 of a 0.8 m ball still
    grid_share = 0.6 ** 3 / (4 / 3 * np.pi * 0.8 ** 3)
    assert known_shares(pair, xyz[1:2], 0.8)[0] == pytest.approx([grid_share / 2, grid_share, grid_share / 2],
                                                                  rel=0.02)
    # a radius under a voxel reads the POI's own voxel
    assert known_shares(pair, xyz[[0, 2]], 0.001)[:, 0].tolist() == [1.0, 0.0]
