"""A plan whose stages shrink leaves no outputs of the stages it dropped beside the redone ones: after fuse + segment,
a plan of fuse alone with another voxel size redid the fuse and left segment/ (and segment.mcap) of the old volume
beside it. Now a redone stage removes the outputs, in the recording's folder, of every stage that reads its outputs
(directly or not) and that the plan no longer runs, kinfu's only: a user's file among them stays, and the redone
stage's manifest entry says what was removed and what was kept."""

from __future__ import annotations

import json
import shutil

from click.testing import CliRunner

from kinfu_cli.batch.engine import stale_stages
from kinfu_cli.batch.plan import load_plan
from kinfu_cli.cli import cli
from kinfu_cli.commands._batch_stages import batch_stages
from kinfu_cli.sim.synth import synthesize

PLAN = """output = "out"
stages = {stages}
recordings = ["a.mcap", "b.mcap"]
[options.fuse]
voxel-size = {voxel}
"""
SEGMENT = """[options.segment]
no-superquadrics = true
viz = true
"""


def _run(plan, scheduler) -> dict:
    run = CliRunner().invoke(cli, ["batch", str(plan), "--scheduler", scheduler, "--quiet"], catch_exceptions=False)
    assert run.exit_code == 0, run.output
    doc = json.loads((plan.parent / "out" / "manifest.json").read_text())
    return {r["output"]: r["stages"] for r in doc["recordings"]}


def test_the_dropped_stages_outputs_go_when_their_input_is_redone(tmp_path, scheduler):
    synthesize(tmp_path / "synth", seed=0, width=32, height=24, frames=4, formats=("mcap",))
    for name in ("a.mcap", "b.mcap"):
        shutil.copy(tmp_path / "synth" / "recording.mcap", tmp_path / name)
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN.format(stages='["fuse", "segment"]', voxel=0.04) + SEGMENT)
    _run(plan, scheduler)
    a, b = tmp_path / "out" / "a", tmp_path / "out" / "b"
    for rec in (a, b):
        assert (rec / "segment" / "segments.json").is_file() and (rec / "segment.mcap").is_file()
    (b / "segment" / "notes.txt").write_text("mine")  # a user's file in kinfu's segment folder
    (a / "notes.txt").write_text("mine too")  # and one beside the outputs

    plan.write_text(PLAN.format(stages='["fuse"]', voxel=0.05))  # segment dropped, the fuse redone
    stages = _run(plan, scheduler)
    for rec in (a, b):
        assert json.loads((rec / "fuse" / "report.json").read_text())["grid"]["voxel_size"] == 0.05
        assert not (rec / "segment" / "segments.json").exists() and not (rec / "segment.mcap").exists()
    assert not (a / "segment").exists()  # before: the segments of the 0.04 m volume stayed
    assert (a / "notes.txt").read_text() == "mine too"
    assert sorted(p.name for p in (b / "segment").iterdir() if not p.name.startswith(".")) == ["notes.txt"]
    assert (b / "segment" / "notes.txt").read_text() == "mine"
    fuse_a, fuse_b = stages[str(a)]["fuse"], stages[str(b)]["fuse"]
    assert fuse_a["status"] == fuse_b["status"] == "ok"
    (said_a,) = [w for w in fuse_a["warnings"] if w.startswith("the segment outputs of an earlier run")]
    assert "removed segment, segment.mcap" in said_a and "segment is not in this plan" in said_a, said_a
    (said_b,) = [w for w in fuse_b["warnings"] if w.startswith("the segment outputs of an earlier run")]
    assert "kept segment/notes.txt" in said_b and "segment/segments.json" in said_b, said_b

    again = _run(plan, scheduler)  # nothing redone: nothing removed, and no word of the earlier removal
    assert again[str(b)]["fuse"]["status"] == "skipped"
    assert not [w for w in again[str(b)]["fuse"]["warnings"] if "earlier run" in w]
    assert (b / "segment" / "notes.txt").read_text() == "mine"

    plan.write_text(PLAN.format(stages='["fuse", "segment"]', voxel=0.05) + SEGMENT)  # segment back: it writes
    stages = _run(plan, scheduler)  # beside the user's file, unforced (the folder is still kinfu's)
    assert stages[str(b)]["segment"]["status"] == "ok" and (b / "segment" / "segments.json").is_file()
    assert (b / "segment" / "notes.txt").read_text() == "mine"


def test_the_stale_stages_are_those_reading_the_redone_one_that_the_recording_does_not_run(tmp_path):
    (tmp_path / "a.mcap").write_bytes(b"")
    (tmp_path / "b.mcap").write_bytes(b"")
    (tmp_path / "plan.toml").write_text(PLAN.format(stages='["fuse", "poi"]', voxel=0.04))
    table = batch_stages()
    rec = load_plan(tmp_path / "plan.toml", table).recordings[0]

    def names(stage):
        return [s.name for s in stale_stages(table, rec, stage)]

    # through others too (eval-segment reads segment); not the combined viewer file, whose name the plan gives
    assert names("fuse") == ["nbv", "segment", "diff", "eval-fusion", "eval-segment"]
    assert names("poi") == ["nbv", "diff", "eval-poi"]
