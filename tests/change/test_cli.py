"""`kinfu diff` end to end: output files and their contract, POI scores, one-line errors, output safety; a
`kinfu synth` before/after pair and a real RGB-D pair with an object edited out."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.core.pois import Poi, write_pois
from kinfu_cli.evaluation.poi import score_pois

VS = 0.01


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _labels(obj_x: int | None) -> np.ndarray:
    lab = np.zeros((50, 40, 30), dtype=np.int8)
    lab[:, :, 8:] = -1
    lab[:, :, 5:8] = 1
    if obj_x is not None:
        lab[obj_x:obj_x + 6, 10:16, 8:14] = 1
        lab[obj_x + 2:obj_x + 4, 12:14, 10:12] = 0
    return lab


@pytest.fixture
def pair(tmp_path) -> tuple[Path, Path]:
    b, a = tmp_path / "before.npz", tmp_path / "after.npz"
    save_ternary(b, TernaryGrid(_labels(5), np.zeros(3), VS, "world"))
    save_ternary(a, TernaryGrid(_labels(35), np.array([0.02, 0.0, 0.0]), VS, "world"))  # placed elsewhere
    return b, a


def test_diff_writes_changes_json_region_plys_and_scores_pois(pair, tmp_path):
    import open3d as o3d

    b, a = pair
    pois = tmp_path / "pois.json"
    write_pois(pois, [Poi(0, [0.08, 0.13, 0.12], 1.0, 5.0), Poi(1, [0.2, 0.35, 0.3], 2.0, 1.0)], "gmm-as", {},
               frame="world")
    out = tmp_path / "d"
    res = run("diff", b, a, "-o", out, "--pois", pois)
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "changes.json").read_text())
    assert [r["kind"] for r in doc["regions"]] in (["removed", "added"], ["added", "removed"])
    assert doc["counts"]["regions"] == {"removed": 1, "added": 1} and doc["warnings"] == []
    for r in doc["regions"]:
        x0 = 5 * VS if r["kind"] == "removed" else 0.02 + 35 * VS  # the after grid starts 2 cm further
        assert r["centroid"][0] == pytest.approx(x0 + 3 * VS, abs=1e-6)
        pc = o3d.io.read_point_cloud(str(out / r["ply"]))
        assert len(pc.points) == r["voxels"] and r["volume_m3"] == pytest.approx(r["voxels"] * VS ** 3)
        assert np.all(np.asarray(pc.points) >= np.array(r["box_min"]) - 1e-9)
    allpc = o3d.io.read_point_cloud(str(out / "changes.ply"))
    assert len(allpc.points) == sum(r["voxels"] for r in doc["regions"])
    assert doc["pois"]["tp"] == 1 and doc["pois"]["fp"] == 1 and doc["pois"]["fn"] == 1
    assert "precision 50.0 %, recall 50.0 %" in res.output
    assert doc["common_box"]["min"] == pytest.approx([0.02, 0.0, 0.0])
    # --json prints the same document; a second run replaces kinfu's own folder
    res = run("diff", b, a, "-o", out, "--json", "--quiet")
    assert res.exit_code == 0 and json.loads(res.stdout)["regions"] == doc["regions"]


def test_identical_volumes_give_no_region_and_say_so(pair, tmp_path):
    b, _ = pair
    res = run("diff", b, b, "-o", tmp_path / "d", "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["regions"] == [] and doc["counts"]["changed_voxels"] == {"removed": 0, "added": 0}
    (warning,) = doc["warnings"]  # 0 changes of a volume against itself is no finding
    assert "the same file" in warning
    assert doc["changes_ply"] is None and not (tmp_path / "d" / "changes.ply").exists()
    assert not list((tmp_path / "d" / "regions").glob("*.ply")) and (tmp_path / "d" / "changes.json").exists()


def test_bad_inputs_are_one_line_errors(pair, tmp_path):
    b, a = pair
    one_line_error(run("diff", tmp_path / "nope.npz", a, "-o", tmp_path / "d"), "nope.npz", "no such")
    txt = tmp_path / "notes.npz"
    txt.write_text("not a volume")
    one_line_error(run("diff", b, txt, "-o", tmp_path / "d"), "notes.npz")
    np.savez(tmp_path / "foreign.npz", a=np.zeros(3))
    one_line_error(run("diff", tmp_path / "foreign.npz", a, "-o", tmp_path / "d"), "foreign.npz",
                   "neither a volume.npz nor a ternary.npz")
    coarse = tmp_path / "coarse.npz"
    save_ternary(coarse, TernaryGrid(_labels(5), np.zeros(3), 0.02, "world"))
    one_line_error(run("diff", b, coarse, "-o", tmp_path / "d"), "coarse.npz", "voxel size 0.02 m", "0.01 m")
    far = tmp_path / "far.npz"
    save_ternary(far, TernaryGrid(_labels(5), np.array([10.0, 0, 0]), VS, "world"))
    one_line_error(run("diff", b, far, "-o", tmp_path / "d"), "far.npz", "does not overlap")
    one_line_error(run("diff", b, a, "-o", tmp_path / "d", "--margin", "-1"), "--margin")
    one_line_error(run("diff", b, a, "-o", tmp_path / "d", "--min-volume", "-1"), "--min-volume")
    one_line_error(run("diff", b, a, "-o", tmp_path / "d", "--pois", tmp_path / "none.json"), "none.json")
    assert not (tmp_path / "d").exists()


def test_a_folder_kinfu_did_not_write_is_refused_without_force(pair, tmp_path):
    b, a = pair
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    one_line_error(run("diff", b, a, "-o", mine), "--force")
    res = run("diff", b, a, "-o", mine, "--force", "--quiet")
    assert res.exit_code == 0, res.output
    assert (mine / "notes.txt").read_text() == "mine" and (mine / "changes.json").exists()
    one_line_error(run("diff", b, a, "-o", tmp_path, "--force"))  # the folder holding the inputs


@pytest.mark.slow
def test_synth_pick_and_place_found_where_the_object_was_and_went(sample_dir, tmp_path):
    """The bundled `kinfu synth` recording: the scan before the hand comes in, a fresh fusion of the views after
    it left; the moved object is one removed region at its old place and one added at its new place, nothing
    else survives, and the hand's POIs point at both (precision = recall = 1)."""
    from kinfu_cli.demo import hand_window
    from kinfu_cli.sim.scenario import load_ground_truth

    rec = sample_dir / "recording.mcap"
    t_in, t_out = hand_window(rec)
    for name, window in (("before", ["--end", f"{t_in:.3f}"]), ("after", ["--start", f"{t_out:.3f}"])):
        res = run("fuse", rec, "-o", tmp_path / name, "--voxel-size", "0.01", "--quiet", *window)
        assert res.exit_code == 0, res.output
    res = run("poi", rec, "-o", tmp_path / "pois.json")
    assert res.exit_code == 0, res.output
    res = run("diff", tmp_path / "before" / "volume.npz", tmp_path / "after" / "volume.npz", "-o", tmp_path / "d",
              "--pois", tmp_path / "pois.json", "--json", "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    gt = load_ground_truth(sample_dir)
    expected = {"pick": "removed", "place": "added"}
    assert len(doc["regions"]) == len(gt.changes) == 2, doc["regions"]
    for change in gt.changes:
        kind = expected[change["kind"]]
        near = [r for r in doc["regions"] if r["kind"] == kind
                and np.linalg.norm(np.subtract(r["centroid"], change["position"])) < 0.05]
        assert len(near) == 1, (change, doc["regions"])
        assert near[0]["volume_m3"] > 1e-4  # a real object, not a speckle
    assert score_pois(np.array([r["centroid"] for r in doc["regions"]]), gt.change_positions) == (2, 0, 0)
    assert doc["pois"]["precision"] == 1.0 and doc["pois"]["recall"] == 1.0 and doc["warnings"] == []
