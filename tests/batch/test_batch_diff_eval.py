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
  {{path = "after/recording.mcap", output = "after", stages = ["fuse", "poi", "diff", "eval-fusion", "eval-poi"],
   before = "scan/recording.mcap", options = {{fuse = {{start = {t_out:.3f}}}}}}},
]
[options.fuse]
voxel-size = 0.01
"""


def _topics(path: Path) -> list[tuple[str, int]]:
    with open(path, "rb") as fh:
        return [(c.topic, m.log_time) for _, c, m in make_reader(fh).iter_messages(log_time_order=True)]


@pytest.mark.slow
def test_diff_eval_and_viewer_stages(sample_dir, scheduler, tmp_path):
    from kinfu_cli.demo import hand_window

    rec = sample_dir / "recording.mcap"
    for name in ("scan", "after"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "recording.mcap").symlink_to(rec)
    (tmp_path / "after" / "ground_truth").symlink_to(sample_dir / "ground_truth", target_is_directory=True)
    t_in, t_out = hand_window(rec)
    # the plan is one TOML inline table per entry, which must stay on one line
    text = PLAN.format(t_in=t_in, t_out=t_out).replace('"eval-poi"],\n   before', '"eval-poi"], before')
    (tmp_path / "plan.toml").write_text(text)
    res = CliRunner().invoke(cli, ["batch", str(tmp_path / "plan.toml"), "--scheduler", scheduler, "--quiet"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "out" / "manifest.json").read_text())
    scan, after = doc["recordings"]
    assert list(scan["stages"]) == ["fuse", "viz"]
    assert list(after["stages"]) == ["fuse", "poi", "diff", "eval-fusion", "eval-poi", "viz"]
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
    assert res.exit_code == 0 and "(0 stages run, 8 skipped)" in res.output, res.output
