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
    assert [r.output.name for r in plan.recordings] == ["tabletop_mcap", "tabletop_bag", "tabletop_ros2",
                                                        "tabletop_after"]
    assert plan.stages == ["fuse", "poi", "nbv", "segment", "diff", "eval-fusion", "eval-poi", "viz"]
    for rec in plan.recordings:
        assert rec.path.exists() and rec.links["ground_truth"].is_dir()
        for s in rec.stages:
            table[s].check(rec, rec.stage_options(s))
    assert plan.recordings[2].stage_options("segment") == {"plot": True, "seed": 1, "viz": True}
    after = plan.recordings[3]
    assert after.stages == ("fuse", "poi", "diff", "eval-poi", "viz")
    assert after.links["before"] == plan.recordings[0].output / "fuse" / "volume.npz"
    assert after.stage_options("fuse") == {"voxel-size": 0.01, "start": 11.04, "viz": True}


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


@pytest.fixture
def lab(folder):
    """sessions/ plus a kinfu synth layout (synth/recording.mcap beside synth/ground_truth/) and a volume file."""
    (folder / "synth" / "ground_truth").mkdir(parents=True)
    (folder / "synth" / "recording.mcap").write_bytes(b"x")
    (folder / "old.npz").write_bytes(b"x")
    return folder


def _full_table():
    from kinfu_cli.commands._batch_stages import batch_stages

    return batch_stages()


def test_diff_before_and_ground_truth_links(lab):
    p = _plan(lab, 'output = "out"\nstages = ["fuse", "poi", "eval-poi"]\nrecordings = [\n'
                   '  {path = "synth/recording.mcap", output = "s"},\n'
                   '  {path = "sessions/day2.mcap", stages = ["fuse", "poi", "diff"], before = "synth/recording.mcap"},\n'
                   '  {path = "sessions/day1.mcap", stages = ["fuse", "diff", "eval-fusion"], before = "old.npz", '
                   'ground-truth = "synth/ground_truth"}]\n')
    plan = load_plan(p, _full_table())
    s, day2, day1 = plan.recordings
    assert s.stages == ("fuse", "poi", "eval-poi") and s.links == {"ground_truth": lab / "synth" / "ground_truth"}
    # diff after the other recording's fuse, on its volume; POIs scored when the recording has them
    assert day2.stages == ("fuse", "poi", "diff") and day2.links["before"] == s.output / "fuse" / "volume.npz"
    assert day2.after == (("diff", 0, "fuse"),)
    table = _full_table()
    assert [label for label, _ in table["diff"].input_paths(day2)] == ["<before>", "fuse/volume.npz", "pois.json"]
    assert day1.links == {"before": lab / "old.npz", "ground_truth": lab / "synth" / "ground_truth"}
    assert day1.after == () and plan.stages == ["fuse", "poi", "diff", "eval-fusion", "eval-poi"]
    assert [label for label, _ in table["diff"].input_paths(day1)] == ["<before>", "fuse/volume.npz"]


@pytest.mark.parametrize("recordings, needles", [
    ('[{path = "sessions/day1.mcap", stages = ["fuse", "diff"]}]', ["recordings[0]", "diff needs 'before'"]),
    ('[{path = "sessions/day1.mcap", before = "old.npz"}]', ["recordings[0]", "diff is not among"]),
    ('[{path = "sessions/day1.mcap", stages = ["fuse", "diff"], before = "sessions/day1.mcap"}]', ["itself"]),
    ('[{path = "sessions/day1.mcap", stages = ["poi"]}, {path = "sessions/day2.mcap", stages = ["fuse", "diff"], '
     'before = "sessions/day1.mcap"}]', ["recordings[1]", "not fused in this plan"]),
    ('[{path = "sessions/day1.mcap", stages = ["fuse", "diff"], before = "gone.npz"}]', ["gone.npz", "no such"]),
    ('[{path = "sessions/day1.mcap", stages = ["fuse", "eval-fusion"]}]',
     ["recordings[0]", "eval-fusion need(s) ground truth", "sessions/ground_truth"]),
    ('[{path = "synth/recording.mcap", stages = ["eval-poi"]}]', ["recordings[0].stages", "eval-poi needs poi"]),
    ('[{path = "synth/recording.mcap", ground-truth = "nowhere"}]', ["ground-truth", "nowhere", "no such folder"]),
    ('[{path = "synth/recording.mcap", stages = ["fuse", "viz"]}]', ["unknown stage 'viz'", "viz = "]),
])
def test_missing_inputs_of_diff_and_eval_are_one_line(lab, recordings, needles):
    p = _plan(lab, f'output = "out"\nstages = ["fuse"]\nrecordings = {recordings}\n')
    with pytest.raises(ConfigError) as info:
        load_plan(p, _full_table())
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(p))
    for n in needles:
        assert n in msg, (n, msg)


def test_viz_adds_one_viewer_stage_per_recording(lab):
    p = _plan(lab, 'output = "out"\nstages = ["fuse", "poi", "nbv"]\nviz = "scene.mcap"\nrecordings = [\n'
                   '  "sessions/day1.mcap", {path = "sessions/day2.mcap", stages = ["fuse", "diff"], before = "old.npz"}]\n'
                   '[options.nbv]\nviz = false\n')
    table = _full_table()
    plan = load_plan(p, table)
    a, b = plan.recordings
    assert a.stages == ("fuse", "poi", "nbv", "viz") and a.links["viz"] == a.output / "scene.mcap"
    # every stage with a viewer file of its own writes it (the plan's false is overridden): viz combines them
    assert all(a.stage_options(s)["viz"] is True for s in ("fuse", "poi", "nbv"))
    assert [label for label, _ in table["viz"].input_paths(a)] == ["fuse.mcap", "pois.mcap", "views.mcap"]
    assert table["viz"].outputs_of(a) == ("scene.mcap",) and table["viz"].claims_of(b) == ("scene.mcap",)
    assert [label for label, _ in table["viz"].input_paths(b)] == ["fuse.mcap"]
    assert load_plan(p, table, viz="other.mcap").recordings[0].links["viz"].name == "other.mcap"  # the CLI wins
    for bad in ("sub/x.mcap", "x.ply", ""):
        with pytest.raises(ConfigError, match="viz: expected a file name ending .mcap"):
            load_plan(p, table, viz=bad)


def test_a_diff_blocked_by_the_other_recordings_fuse_names_it(lab):
    from kinfu_cli.batch.engine import run_task

    p = _plan(lab, 'output = "out"\nstages = ["fuse"]\nrecordings = ["sessions/day1.mcap", {path = "sessions/day2.mcap", '
                   'stages = ["fuse", "diff"], before = "sessions/day1.mcap"}]\n')
    day1, day2 = load_plan(p, _full_table()).recordings
    own = {"stage": "fuse", "status": "ok", "folder": str(day2.output)}
    other = {"stage": "fuse", "status": "failed", "folder": str(day1.output)}
    entry = run_task(_full_table()["diff"], day2, {}, None, False, own, other)
    assert entry["status"] == "blocked" and entry["error"] == f"needs fuse of {day1.output}, which did not finish"
