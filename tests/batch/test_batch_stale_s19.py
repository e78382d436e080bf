"""A stage that fails on a re-run does not leave its earlier run's outputs, complete-looking, beside the other
stages' new results (a segment of the old fuse beside the new fuse)."""

from __future__ import annotations

import json
import shutil

from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.sim.synth import synthesize

PLAN = """output = "out"
stages = ["fuse", "segment"]
recordings = ["a.mcap"]
[options.fuse]
voxel-size = {voxel}
[options.segment]
no-superquadrics = true
{segment}
"""


def test_a_failed_stage_leaves_no_outputs_of_an_earlier_run(tmp_path, scheduler):
    synthesize(tmp_path / "synth", seed=0, width=32, height=24, frames=4, formats=("mcap",))
    shutil.copy(tmp_path / "synth" / "recording.mcap", tmp_path / "a.mcap")
    plan = tmp_path / "plan.toml"
    plan.write_text(PLAN.format(voxel=0.04, segment=""))
    run = CliRunner().invoke(cli, ["batch", str(plan), "--scheduler", scheduler, "--quiet"], catch_exceptions=False)
    out = tmp_path / "out" / "a"
    assert run.exit_code == 0, run.output
    (out / "notes.txt").write_text("mine")
    assert (out / "segment" / "segments.json").is_file()
    plan.write_text(PLAN.format(voxel=0.05, segment="min-weight = 255"))  # the new fuse, then a segment that fails
    run = CliRunner().invoke(cli, ["batch", str(plan), "--scheduler", scheduler, "--quiet"], catch_exceptions=False)
    assert run.exit_code == 1
    assert json.loads((out / "fuse" / "report.json").read_text())["grid"]["voxel_size"] == 0.05
    assert not (out / "segment").exists()  # before: segments.json of the 0.04 m fuse stayed
    entry = json.loads((tmp_path / "out" / "manifest.json").read_text())["recordings"][0]["stages"]["segment"]
    # removed when the fuse was redone (its outputs change), before the segment stage ran and failed
    assert entry["status"] == "failed" and "no surface" in entry["error"]
    assert (out / "notes.txt").read_text() == "mine"
