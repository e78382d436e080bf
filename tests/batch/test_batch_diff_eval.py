"""`kinfu batch` with diff, the evaluations and one viewer file per recording, on the bundled synthetic
recording: the scan before the hand comes in and the views after it left are two plan entries; the after
entry's diff against the scan finds the moved object where it was and where it went, its POIs point at both,
and the evaluations and viewer files agree with what the stages wrote."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

from kinfu_cli.cli import cli
from kinfu_cli.sim.scenario import load_ground_truth

PLAN = """output = "out"
stages = ["fuse"]
viz = "scene.mcap"
recordings = [
  {{path = "scan/recording.mcap", output = "scan", options = {{fuse = {{end = {t_in:.3f}}}}}}},
  {{path = "after/recording.mcap", output = "after", stages = ["fuse", "poi", "segment", "diff", "eval-fusion",
   "eval-poi", "eval-nbv", "eval-segment"], before = "scan/recording.mcap",
   options = {{fuse = {{start = {t_out:.3f}}}}}}},
]
[options.fuse]
voxel-size = 0.01
[options.eval-nbv]  # a tiny closed loop: 64x48 images, 3 cm voxels, a 4 x 3 x 2 viewing sphere
strategy = "poi,random"
views = 1
width = 64
height = 48
voxel-size = 0.03
scan-every = 4
lon-step = 90
lat-step = 45
roll-step = 180
"""


def _topics(path: Path) -> list[tuple[str, int]]:
    with open(path, "rb") as fh:
        return [(c.topic, m.log_time) for _, c, m in make_reader(fh).iter_messages(log_time_order=True)]


def _ground_truth_with_labels(sample_dir: Path, folder: Path) -> Path:
    """The sample's ground truth (links) plus the labels.npz kinfu synth writes today (the sample predates it):
    the per-voxel labels of the same seeded scene."""
    from kinfu_cli.sim.scenario import make_scenario, write_scene_voxel_labels

    folder.mkdir()
    for p in (sample_dir / "ground_truth").iterdir():
        (folder / p.name).symlink_to(p, target_is_directory=p.is_dir())
    seed = json.loads((sample_dir / "ground_truth" / "changes.json").read_text())["seed"]
    write_scene_voxel_labels(folder / "labels.npz", make_scenario(seed, width=64, height=48, frames=2).scene_after)
    return folder


@pytest.mark.slow
def test_diff_eval_and_viewer_stages(sample_dir, scheduler, tmp_path):
    from kinfu_cli.demo import hand_window

    rec = sample_dir / "recording.mcap"
    for name in ("scan", "after"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "recording.mcap").symlink_to(rec)
    _ground_truth_with_labels(sample_dir, tmp_path / "after" / "ground_truth")
    t_in, t_out = hand_window(rec)
    # the plan is one TOML inline table per entry, which must stay on one line
    text = PLAN.format(t_in=t_in, t_out=t_out).replace(",\n   ", ", ")
    (tmp_path / "plan.toml").write_text(text)
    res = CliRunner().invoke(cli, ["batch", str(tmp_path / "plan.toml"), "--scheduler", scheduler, "--quiet"],
                             catch_exceptions=False)
    doc = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert res.exit_code == 0, [(s, e["error"]) for r in doc["recordings"] for s, e in r["stages"].items()
                                if e["status"] != "ok"]
    scan, after = doc["recordings"]
    assert list(scan["stages"]) == ["fuse", "viz"]
    assert list(after["stages"]) == ["fuse", "poi", "segment", "diff", "eval-fusion", "eval-nbv", "eval-segment",
                                     "eval-poi", "viz"]
    assert all(e["status"] == "ok" for r in (scan, after) for e in r["stages"].values())
    st = after["stages"]
    # the moved object: one region removed where it was, one added where it went, both pointed at by the POIs
    assert st["diff"]["numbers"] == {"removed": 1, "added": 1, "poi_precision": 1.0, "poi_recall": 1.0}
    gt = load_ground_truth(sample_dir)
    changes = json.loads((tmp_path / "out" / "after" / "diff" / "changes.json").read_text())
    for change in gt.changes:
        kind = {"pick": "removed", "place": "added"}[change["kind"]]
        assert any(r["kind"] == kind and np.linalg.norm(np.subtract(r["centroid"], change["position"])) < 0.05
                   for r in changes["regions"]), (change, changes["regions"])
    # the evaluations: the POIs against the true changes, the fused surface against the true after scene
    assert st["eval-poi"]["numbers"] == {"precision": 1.0, "recall": 1.0, "tp": 2, "fp": 0, "fn": 0}
    fusion = st["eval-fusion"]["numbers"]
    assert fusion["accuracy_mean_m"] < 0.01 and fusion["precision"] > 0.9
    ev = json.loads((tmp_path / "out" / "after" / "eval_fusion.json").read_text())
    assert ev["reconstruction"]["precision"] == fusion["precision"]
    # the NBV loop on the recording's true scene: both strategies took their view and revealed unknown space,
    # the numbers are those of eval_nbv.json
    loop = json.loads((tmp_path / "out" / "after" / "eval_nbv.json").read_text())
    assert set(loop["strategies"]) == {"poi", "random"}
    for name, r in loop["strategies"].items():
        assert r["final_unknown"] < r["initial_unknown"]
        assert st["eval-nbv"]["numbers"][f"{name}_unknown_left"] == r["final_unknown"]
    # the segmentation of the fused after-scene against the true labels: the table's four objects are found
    seg = st["eval-segment"]["numbers"]
    ev = json.loads((tmp_path / "out" / "after" / "eval_segment.json").read_text())
    assert seg["object_recall"] == ev["object_recall"] and seg["bce"] == ev["bce"]
    assert seg["objects_total"] == 4 and seg["objects_found"] >= 3 and seg["boundary_precision"] > 0.5
    assert ev["input"]["ground_truth"].endswith("labels.npz")
    # one viewer file per recording: the mesh and camera of fuse, the hand and POIs of poi, on one clock
    topics = _topics(tmp_path / "out" / "after" / "scene.mcap")
    names = {t for t, _ in topics}
    assert {"/kinfu/mesh", "/kinfu/camera_trajectory", "/kinfu/hand_trajectory", "/kinfu/pois", "/tf"} <= names
    assert min(ns for _, ns in topics) > 0
    assert after["viewer"] == str(tmp_path / "out" / "after" / "scene.mcap")
    assert {t for t, _ in _topics(tmp_path / "out" / "scan" / "scene.mcap")} >= {"/kinfu/mesh", "/tf"}
    # resumed: nothing changed, nothing runs
    res = CliRunner().invoke(cli, ["batch", str(tmp_path / "plan.toml"), "--scheduler", scheduler, "--quiet"],
                             catch_exceptions=False)
    assert res.exit_code == 0 and "(0 stages run, 11 skipped)" in res.output, res.output
