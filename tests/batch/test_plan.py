"""The plan: TOML and YAML read alike, globs expand, and every mistake is one line naming the plan entry,
found before any work."""

from __future__ import annotations

from pathlib import Path

import pytest

from kinfu_cli.batch.plan import load_plan
from kinfu_cli.batch.stages import RECORDING, StageRun, StageSpec
from kinfu_cli.core.errors import ConfigError


def _noop_check(rec, options):
    return None


def _noop_run(rec, options, force):
    return StageRun()


TABLE = {name: StageSpec(name, needs, (RECORDING,), (f"{name}.json",), (f"{name}.json",), _noop_check, _noop_run)
         for name, needs in (("fuse", ()), ("poi", ()), ("nbv", ("fuse", "poi")), ("segment", ("fuse",)))}


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "sessions").mkdir()
    for name in ("day1.mcap", "day2.mcap", "day1.bag"):
        (tmp_path / "sessions" / name).write_bytes(b"x")
    return tmp_path


def _plan(folder: Path, text: str, name: str = "plan.toml") -> Path:
    p = folder / name
    p.write_text(text)
    return p


def test_toml_and_yaml_give_the_same_plan(folder):
    toml = _plan(folder, 'output = "out"\nstages = ["fuse", "segment"]\n'
                         'recordings = ["sessions/*.mcap", {path = "sessions/day1.bag", output = "bag1", '
                         'options = {fuse = {voxel_size = 0.01}}}]\n[options.fuse]\nvoxel-size = 0.02\nend = 6\n')
    yaml = _plan(folder, "output: out\nstages: [fuse, segment]\nrecordings:\n  - sessions/*.mcap\n"
                         "  - {path: sessions/day1.bag, output: bag1, options: {fuse: {voxel_size: 0.01}}}\n"
                         "options:\n  fuse: {voxel-size: 0.02, end: 6}\n", "plan.yaml")
    a, b = load_plan(toml, TABLE), load_plan(yaml, TABLE)
    assert a.recordings == b.recordings and a.stages == b.stages == ["fuse", "segment"]
    outs = [r.output.relative_to(folder / "out").as_posix() for r in a.recordings]
    assert outs == ["sessions/day1", "sessions/day2", "bag1"]
    # common options, overridden per entry (underscore and dash spellings are one option)
    assert a.recordings[0].stage_options("fuse") == {"voxel-size": 0.02, "end": 6}
    assert a.recordings[2].stage_options("fuse") == {"voxel-size": 0.01, "end": 6}
    assert a.recordings[0].stage_options("segment") == {}


def test_command_line_output_wins(folder):
    p = _plan(folder, 'output = "out"\nstages = ["poi"]\nrecordings = ["sessions/day1.mcap"]\n')
    assert load_plan(p, TABLE, folder / "elsewhere").recordings[0].output == folder / "elsewhere/sessions/day1"


@pytest.mark.parametrize("text, needles", [
    ('stages = ["fuse", "teleport"]\nrecordings = ["sessions/day1.mcap"]', ["stages", "unknown stage 'teleport'"]),
    ('stages = ["nbv", "fuse"]\nrecordings = ["sessions/day1.mcap"]', ["stages", "nbv needs poi"]),
    ('stages = ["fuse"]\nrecordings = ["sessions/nope.mcap"]', ["recordings[0]", "nope.mcap", "no such file"]),
    ('stages = ["fuse"]\nrecordings = ["sessions/*.bagz"]', ["recordings[0]", "matches nothing"]),
    ('stages = ["fuse"]\nrecordings = ["sessions/day1.mcap", "sessions/day1.bag"]',
     ["recordings[1]", "would both write to", "day1"]),
    ('stages = ["fuse"]\nrecordings = [{path = "sessions/day1.mcap", output = "x"}, '
     '{path = "sessions/day2.mcap", output = "x"}]', ["recordings[1]", "would both write to"]),
    ('stages = ["fuse"]\nrecordings = [{path = "sessions/*.mcap", output = "x"}]', ["names one folder"]),
    ('stages = ["fuse"]\nrecordings = ["sessions/day1.mcap"]\n[options.segmnet]\nseed = 1', ["options.segmnet",
                                                                                          "unknown stage"]),
    ('stages = ["fuse"]\nrecordings = ["sessions/day1.mcap"]\nworkers = 3', ["workers", "unknown key"]),
    ('stages = ["fuse"]\nrecordings = []', ["recordings", "non-empty"]),
    ('stages = "fuse"\nrecordings = ["sessions/day1.mcap"]\noutput = "../../.."', []),
])
def test_bad_plans_are_one_line_errors(folder, text, needles):
    if not needles:  # a plan may put its output anywhere; only its entries' folders must stay inside
        load_plan(_plan(folder, text), TABLE)
        return
    text = text if "output" in text.split("\n")[0] else 'output = "out"\n' + text
    with pytest.raises(ConfigError) as info:
        load_plan(_plan(folder, text), TABLE)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(folder / "plan.toml"))
    for n in needles:
        assert n in msg, (n, msg)


def test_unreadable_plans(folder):
    for name, text, needle in (("p.toml", "stages = [", "not valid TOML"), ("p.yaml", "a: [", "not valid YAML"),
                               ("p.json", "{}", "expected a .toml"), ("p.toml", 'stages = ["poi"]\nrecordings = '
                                                                    '["sessions/day1.mcap"]', "no output folder")):
        with pytest.raises(ConfigError, match=needle):
            load_plan(_plan(folder, text, name), TABLE)


def test_the_example_plan_is_valid():
    """examples/batch_plan.toml names the sample recordings and options every command accepts."""
    from kinfu_cli.commands._batch_stages import batch_stages

    table = batch_stages()
    example = Path(__file__).resolve().parents[2] / "examples" / "batch_plan.toml"
    plan = load_plan(example, table)
    assert [r.output.name for r in plan.recordings] == ["tabletop_mcap", "tabletop_bag", "tabletop_ros2"]
    assert plan.stages == ["fuse", "poi", "nbv", "segment"]
    for rec in plan.recordings:
        assert rec.path.exists()
        for s in rec.stages:
            table[s].check(rec, rec.stage_options(s))
    assert plan.recordings[2].stage_options("segment") == {"plot": True, "seed": 1}


def test_viewer_files_are_one_per_recording_and_stage(tmp_path):
    """`viz = true` in a plan's stage options writes that stage's viewer file into the recording's folder."""
    from kinfu_cli.commands._batch_stages import _option_args

    out = tmp_path / "rec"
    assert _option_args("fuse", out, {"viz": True}) == ["--viz", str(out / "fuse.mcap")]
    assert _option_args("nbv", out, {"viz": True, "plot": True}) == ["--viz", str(out / "views.mcap"), "--plot",
                                                                     str(out / "views.png")]
    assert _option_args("segment", out, {"viz": False}) == []
    with pytest.raises(ConfigError, match="expected true"):
        _option_args("poi", out, {"viz": "elsewhere.mcap"})
