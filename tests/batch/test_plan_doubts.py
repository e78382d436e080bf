"""Options for a stage that never runs are refused naming the plan, the stage and its options (they were neither
checked nor used); options for a stage only some recordings run still apply to those."""

from __future__ import annotations

import pytest

from kinfu_cli.batch.plan import load_plan
from kinfu_cli.batch.stages import RECORDING, StageRun, StageSpec
from kinfu_cli.core.errors import ConfigError

TABLE = {name: StageSpec(name, needs, (RECORDING,), (f"{name}.json",), (f"{name}.json",), lambda r, o: None,
                         lambda r, o, f: StageRun())
         for name, needs in (("fuse", ()), ("poi", ()), ("nbv", ("fuse", "poi")), ("segment", ("fuse",)))}


@pytest.fixture
def plan(tmp_path):
    (tmp_path / "a.mcap").write_bytes(b"x")
    (tmp_path / "b.mcap").write_bytes(b"x")

    def write(text: str):
        p = tmp_path / "plan.toml"
        p.write_text('output = "out"\n' + text)
        return p
    return write


def test_common_options_for_a_stage_no_recording_runs_are_refused(plan):
    p = plan('stages = ["fuse", "poi"]\nrecordings = ["a.mcap"]\n[options.segment]\nseed = 1\nplot = true\n')
    with pytest.raises(ConfigError) as exc:
        load_plan(p, TABLE)
    msg = str(exc.value)
    assert str(p) in msg and "options.segment" in msg and "seed, plot" in msg and "no recording" in msg


def test_an_entrys_options_for_a_stage_it_does_not_run_are_refused(plan):
    p = plan('stages = ["fuse", "segment"]\nrecordings = ["a.mcap", {path = "b.mcap", stages = ["fuse"], '
             'options = {segment = {seed = 1}}}]\n')
    with pytest.raises(ConfigError) as exc:
        load_plan(p, TABLE)
    msg = str(exc.value)
    assert str(p) in msg and "recordings[1].options.segment" in msg and "seed" in msg and "b.mcap" in msg


def test_common_options_apply_to_the_recordings_that_run_the_stage(plan):
    p = plan('stages = ["fuse", "segment"]\nrecordings = ["a.mcap", {path = "b.mcap", stages = ["fuse"]}]\n'
             '[options.segment]\nseed = 1\n')
    a, b = load_plan(p, TABLE).recordings
    assert a.stage_options("segment") == {"seed": 1} and b.stage_options("segment") == {}
