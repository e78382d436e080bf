"""Ctrl-C (or a killed run) right after a stage was redone leaves no output of an earlier run made from that stage's
old result: the later stages' old outputs are removed before the stage is redone, not when they fail."""

from __future__ import annotations

import json
import shutil

from click.testing import CliRunner

from kinfu_cli.batch import engine
from kinfu_cli.batch.plan import load_plan
from kinfu_cli.cli import cli
from kinfu_cli.commands._batch_stages import batch_stages
from kinfu_cli.sim.synth import synthesize

PLAN = """output = "out"
stages = ["fuse", "poi", "segment", "nbv"]
recordings = ["a.mcap"]
[options.fuse]
voxel-size = {voxel}
[options.segment]
no-superquadrics = true
[options.nbv]
lon-step = 90
roll-step = 180
lat-step = 30
"""


def test_ctrl_c_after_a_redone_fuse_leaves_no_segment_or_views_of_the_old_fuse(tmp_path, scheduler, monkeypatch):
    synthesize(tmp_path / "synth", seed=0, width=32, height=24, frames=4, formats=("mcap",))
    shutil.copy(tmp_path / "synth" / "recording.mcap", tmp_path / "a.mcap")
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN.format(voxel=0.04))
    run = CliRunner().invoke(cli, ["batch", str(plan), "--scheduler", scheduler, "--quiet"], catch_exceptions=False)
    out = tmp_path / "out" / "a"
    assert run.exit_code == 0, run.output
    poi_before = (out / "pois.json").stat().st_mtime_ns
    assert (out / "segment" / "segments.json").is_file() and (out / "views.json").is_file()
    plan.write_text(PLAN.format(voxel=0.05))  # the fuse is redone; poi does not read it

    build = engine.build_manifest

    def interrupted_after_fuse(plan_, entries, *a, **k):  # Ctrl-C as the new fuse's result comes in
        if (0, "fuse") in entries and entries[(0, "fuse")]["status"] == "ok":
            raise KeyboardInterrupt
        return build(plan_, entries, *a, **k)

    monkeypatch.setattr(engine, "build_manifest", interrupted_after_fuse)
    run = CliRunner().invoke(cli, ["batch", str(plan), "--scheduler", scheduler, "--quiet"])
    assert run.exit_code == 130, run.output
    assert json.loads((out / "fuse" / "report.json").read_text())["grid"]["voxel_size"] == 0.05
    fused = (out / "fuse" / "volume.npz").stat().st_mtime_ns
    # whatever of segment / nbv is there was made from the new fuse (a worker may finish a task after Ctrl-C)
    for later in (out / "segment" / "segments.json", out / "views.json"):
        assert not later.exists() or later.stat().st_mtime_ns >= fused, later
    assert (out / "pois.json").stat().st_mtime_ns == poi_before  # not downstream of the fuse: kept


def test_the_stages_after_a_task_include_the_ones_that_read_it_through_others(tmp_path):
    (tmp_path / "a.mcap").write_bytes(b"")
    (tmp_path / "plan.toml").write_text(PLAN.format(voxel=0.04))
    table = batch_stages()
    graph = engine.task_graph(load_plan(tmp_path / "plan.toml", table), table)
    later = engine.dependents(graph)
    assert set(later[(0, "fuse")]) == {(0, "segment"), (0, "nbv")}
    assert set(later[(0, "poi")]) == {(0, "nbv")} and later[(0, "nbv")] == []
