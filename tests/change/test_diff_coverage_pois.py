"""`kinfu diff` says what it could not compare: the share of each volume's observed voxels outside the other's
grid (a warning above MAX_OUTSIDE_BOX), POIs there left unscored, precision / recall / F1 null when their
denominator is 0, and a POI far outside both volumes refused (as `kinfu nbv` refuses it)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.change.diff import diff_grids
from kinfu_cli.cli import cli
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.core.pois import Poi, write_pois

VS = 0.01


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _labels(nx: int, objects_x=()) -> np.ndarray:
    """A table (z 5-8) under free space, unknown below it; a hollow 6-voxel cube on it at each x."""
    lab = np.zeros((nx, 40, 30), dtype=np.int8)
    lab[:, :, 8:] = -1
    lab[:, :, 5:8] = 1
    for x in objects_x:
        lab[x:x + 6, 10:16, 8:14] = 1
        lab[x + 2:x + 4, 12:14, 10:12] = 0
    return lab


def _before() -> TernaryGrid:
    return TernaryGrid(_labels(50, (5, 35)), np.zeros(3), VS, "world")  # cubes at x 0.05 and 0.35 m


def _after_right() -> TernaryGrid:
    """Both cubes gone, but the grid covers x 0.30..0.50 m only: the cube at 0.05 m lies outside it."""
    return TernaryGrid(_labels(20), np.array([0.30, 0.0, 0.0]), VS, "world")


def _write(tmp_path, grids: dict, pois: list[Poi] | None = None):
    paths = []
    for name, g in grids.items():
        save_ternary(tmp_path / name, g)
        paths.append(tmp_path / name)
    if pois is not None:
        write_pois(tmp_path / "pois.json", pois, "gmm-as", {}, frame="world")
    return paths


def test_share_of_each_volume_outside_the_common_box_is_reported_and_warned():
    r = diff_grids(_before(), _after_right(), names=("b.npz", "a.npz"))
    doc = r.to_json()
    ov = doc["overlap"]
    assert [x["kind"] for x in doc["regions"]] == ["removed"]  # only the cube inside the after grid is seen
    # 20 of the before grid's 50 x-slabs lie in the common box; all of the after grid does
    assert ov["before"]["in_common_box_fraction"] == pytest.approx(20 / 50, abs=1e-3)
    # a table slab of 1000 known voxels per x, less the 8 unknown inside each hollow cube
    assert (ov["observed_before"], ov["before"]["in_common_box"]) == (50 * 1000 - 2 * 8, 20 * 1000 - 8)
    assert ov["after"]["in_common_box_fraction"] == 1.0
    assert ov["before"]["compared_fraction"] == pytest.approx(ov["observed_both"] / ov["observed_before"], abs=1e-4)
    assert ov["fraction"] > 0.99  # the old overlap figure says nothing is missing
    (warning,) = [w for w in r.warnings if "not compared" in w]
    assert warning.startswith("b.npz: ") and "(60 %" in warning and "outside a.npz's grid" in warning
    # a volume shifted by a few voxels leaves less than MAX_OUTSIDE_BOX out: no warning
    from kinfu_cli.change.diff import MAX_OUTSIDE_BOX

    shifted = TernaryGrid(_labels(50), np.array([0.05, 0.0, 0.0]), VS, "world")
    r = diff_grids(_before(), shifted)
    assert 1 - r.pair.in_box_fraction("before") < MAX_OUTSIDE_BOX
    assert not [w for w in r.warnings if "not compared" in w]


def test_pois_outside_the_compared_box_are_not_false_positives(tmp_path):
    pois = [Poi(0, [0.38, 0.13, 0.11], 1.0, 1.0),  # on the removed cube: true positive
            Poi(1, [0.08, 0.13, 0.11], 2.0, 1.0),  # on the cube outside the after grid: cannot be judged
            Poi(2, [0.29, 0.13, 0.11], 3.0, 1.0),  # just outside the common box, 6 cm from the region: scored
            Poi(3, [0.47, 0.35, 0.25], 4.0, 1.0)]  # inside, near no change: false positive
    b, a = _write(tmp_path, {"b.npz": _before(), "a.npz": _after_right()}, pois)
    res = run("diff", b, a, "-o", tmp_path / "d", "--pois", tmp_path / "pois.json")
    assert res.exit_code == 0, res.output
    p = json.loads((tmp_path / "d" / "changes.json").read_text())["pois"]
    assert (p["tp"], p["fp"], p["fn"]) == (2, 1, 0)  # the old scoring: fp 2
    assert p["precision"] == pytest.approx(2 / 3) and p["recall"] == 1.0
    assert (p["pois"], p["pois_scored"], p["pois_outside_common_box"]) == (4, 3, 1)
    assert [x["scored"] for x in p["per_poi"]] == [True, False, True, True]
    assert [x["id"] for x in p["per_poi"]] == [0, 1, 2, 3]
    assert "kinfu: warning: " in res.output and "1 of 4 POIs (id 1) lie outside the common box" in res.output
    assert "3 scored" in res.output


def test_undefined_precision_recall_f1_are_null_with_a_warning(tmp_path):
    g = TernaryGrid(_labels(50, (5,)), np.zeros(3), VS, "world")
    h = TernaryGrid(_labels(50, (5,)), np.zeros(3), VS, "world")
    h.labels[40, 30, 20] = 0  # not identical, still no change
    b, a = _write(tmp_path, {"b.npz": g, "a.npz": h}, [Poi(0, [0.08, 0.13, 0.12], 1.0, 1.0)])
    res = run("diff", b, a, "-o", tmp_path / "d", "--pois", tmp_path / "pois.json", "--json", "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    p = doc["pois"]
    assert doc["regions"] == [] and p["fp"] == 1
    assert p["precision"] == 0.0 and p["recall"] is None and p["f1"] is None  # was recall 0.0, f1 0.0
    assert any("no change region was found, so recall and F1 are undefined" in w for w in doc["warnings"])
    res = run("diff", b, a, "-o", tmp_path / "d2", "--pois", tmp_path / "pois.json")
    assert "recall undefined, F1 undefined" in res.output

    write_pois(tmp_path / "none.json", [], "gmm-as", {}, frame="world")
    moved = TernaryGrid(_labels(50, (30,)), np.zeros(3), VS, "world")
    (c,) = _write(tmp_path, {"c.npz": moved})
    res = run("diff", b, c, "-o", tmp_path / "d3", "--pois", tmp_path / "none.json", "--json", "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    p = doc["pois"]
    assert p["pois"] == 0 and p["changes"] == 2 and p["fn"] == 2
    assert p["precision"] is None and p["f1"] is None and p["recall"] == 0.0  # was precision 0.0
    assert any("none.json: the file holds no POI" in w for w in doc["warnings"])


def test_a_poi_far_outside_both_volumes_is_a_one_line_error(tmp_path):
    b, a = _write(tmp_path, {"b.npz": _before(), "a.npz": _after_right()},
                  [Poi(0, [0.38, 0.13, 0.11], 1.0, 1.0), Poi(7, [50.0, 40.0, 10.0], 2.0, 1.0)])
    line = one_line_error(run("diff", b, a, "-o", tmp_path / "d", "--pois", tmp_path / "pois.json"),
                          "pois.json", "POI 7", "outside both volumes", "match radius 0.2 m")
    assert "b.npz" in line and "a.npz" in line
    assert not (tmp_path / "d").exists()
    # 15 cm outside both grids, within the match radius: allowed (a change at the grid's edge may be near it)
    write_pois(tmp_path / "near.json", [Poi(0, [0.65, 0.2, 0.1], 1.0, 1.0)], "gmm-as", {}, frame="world")
    res = run("diff", b, a, "-o", tmp_path / "d", "--pois", tmp_path / "near.json", "--json", "--quiet")
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["pois"]["pois_outside_common_box"] == 1
