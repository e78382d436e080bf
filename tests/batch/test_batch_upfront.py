"""`kinfu batch` refuses bad input before any work.

- Option values out of the library's ranges: each stage's command builds and validates its parameter objects
  without reading an input. Before, such values passed the check (click parses only the type), failed inside the
  Dask task, and the recording was marked failed (exit 1).
- Output folders it did not write: the batch output folder and each recording's folder follow the single
  commands' rule (core.ownership). An existing folder holding a user's files and no kinfu ownership record is
  refused unless --force; with --force the user's files stay; a folder batch wrote into is taken again (resume).
  Before, batch wrote into any existing folder."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.commands._batch_stages import _COMMANDS
from kinfu_cli.core.atomic import write_json
from kinfu_cli.core.ownership import mark_folder_output

# stage -> (the stages its plan lists, an option line out of the library's range, what the error line names)
BAD = {
    "fuse": (["fuse"], "voxel-size = -1", "fuse: voxel-size: expected a positive length in metres, got -1"),
    "poi": (["poi"], "max-components = 0", "poi: max-components: expected an integer >= 1"),
    "nbv": (["fuse", "poi", "nbv"], "lat-step = 0", "nbv: lat-step: expected a step in (0, 360] degrees, got 0"),
    "segment": (["fuse", "segment"], "min-segment-points = -3", "segment: min-segment-points: must be >= 1, got -3"),
    "diff": (["fuse", "diff"], "margin = -1", "diff: margin: expected an integer >= 0"),
    "eval-fusion": (["fuse", "eval-fusion"], "threshold = 0", "eval-fusion: threshold: expected a finite number > 0"),
    "eval-nbv": (["eval-nbv"], "views = 0", "eval-nbv: views: expected an integer >= 1"),
    "eval-segment": (["fuse", "segment", "eval-segment"], "cover = 2",
                     "eval-segment: cover: expected a number in (0, 1], got 2"),
}
# more values per stage that used to pass the check (one stage each is enough for the rule; these pin the
# parameter objects each command builds: the grid, the depth range, the detector, the sphere, the camera...)
MORE = [
    ("fuse", "truncation = 0", "fuse: truncation: expected a finite number > 0"),
    ("fuse", "min-depth = 5", "fuse: min-depth/max-depth: expected 0 <= min < max"),
    ("fuse", 'origin = "1e9,0,0"', "fuse: origin: expected finite x,y,z within"),
    ("fuse", 'max-lost = "200%"', "fuse: max-lost: expected a share in [0, 1]"),
    ("fuse", 'intrinsics = "525,-1,320,240"', "fuse: intrinsics: expected fx,fy,cx,cy"),
    ("poi", 'workspace = "1,2"', "poi: workspace: expected six numbers"),
    ("nbv", "clearance = -1", "nbv: clearance: expected a finite number >= 0"),
    ("nbv", "min-range = 9", "nbv: min-range/max-range: expected 0 <= min < max"),
    ("segment", 'sq-exponent-bounds = "3,1"', "segment: sq-exponent-bounds: expected 0 < lo < hi <= 2"),
    ("diff", "match-radius = 0", "diff: match-radius: expected a finite number > 0"),
    ("eval-nbv", "lon-step = 0", "eval-nbv: lon-step: expected a step in (0, 360]"),
    ("eval-segment", "t-eval = 0", "eval-segment: t-eval: expected a number in (0, 1]"),
]


@pytest.fixture
def workspace(tmp_path) -> Path:
    """A plan folder whose inputs are empty files: nothing may be read before the options are checked."""
    gt = tmp_path / "recs" / "ground_truth"
    gt.mkdir(parents=True)
    for name in ("a.mcap", "ground_truth/labels.npz", "ground_truth/changes.json", "ground_truth/camera_poses.txt"):
        (tmp_path / "recs" / name).touch()
    (tmp_path / "before.npz").touch()
    return tmp_path


def _plan(ws: Path, stages: list[str], stage: str, line: str) -> Path:
    rec = '{path = "recs/a.mcap", before = "before.npz"}' if "diff" in stages else '"recs/a.mcap"'
    plan = ws / "plan.toml"
    plan.write_text(f'output = "out"\nstages = {json.dumps(stages)}\nrecordings = [{rec}]\n[options.{stage}]\n{line}\n')
    return plan


def _batch(*args):
    return CliRunner().invoke(cli, ["batch", *map(str, args), "--quiet"], catch_exceptions=False)


def test_every_stage_has_a_case():
    assert set(BAD) == set(_COMMANDS)


@pytest.mark.parametrize("stage", sorted(BAD))
def test_out_of_range_value_is_refused_before_any_work(stage, workspace, connects):
    stages, line, needle = BAD[stage]
    plan = _plan(workspace, stages, stage, line)
    one_line_error(_batch(plan), f"{plan}: recordings[0] {workspace / 'recs' / 'a.mcap'}: {needle}")
    assert connects == [] and not (workspace / "out").exists()


@pytest.mark.parametrize("stage, line, needle", MORE)
def test_more_values_checked_up_front(stage, line, needle, workspace, connects):
    plan = _plan(workspace, BAD[stage][0], stage, line)
    one_line_error(_batch(plan), f"{plan}: recordings[0] {workspace / 'recs' / 'a.mcap'}: {needle}")
    assert connects == [] and not (workspace / "out").exists()


def test_good_values_pass_the_check(workspace, connects):
    """The check refuses only what the command refuses: the plan's own values get as far as the cluster."""
    plan = _plan(workspace, ["fuse", "poi", "nbv", "segment", "diff", "eval-fusion", "eval-nbv", "eval-segment"],
                 "fuse", "voxel-size = 0.04\nmin-depth = 0.2\n[options.nbv]\nlat-step = 30\n[options.segment]\n"
                         "no-superquadrics = true")
    one_line_error(_batch(plan), "connected to a cluster")
    assert len(connects) == 1


def _listing(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): p.read_text() if p.is_file() else "/" for p in sorted(folder.rglob("*"))}


def test_foreign_output_folder_is_refused_unless_force(workspace, connects):
    plan = _plan(workspace, ["fuse"], "fuse", "voxel-size = 0.04")
    out = workspace / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    before = _listing(out)
    one_line_error(_batch(plan), f"{out}: an existing folder that kinfu did not write", "--force")
    one_line_error(_batch(plan, "-o", out), f"{out}: an existing folder", "--force")
    assert _listing(out) == before and connects == []
    one_line_error(_batch(plan, "--force"), "connected to a cluster")  # --force gets past the checks
    assert (out / "notes.txt").read_text() == "mine"


def test_foreign_recording_folder_is_refused_unless_force(workspace, connects):
    plan = _plan(workspace, ["fuse"], "fuse", "voxel-size = 0.04")
    out = workspace / "out"
    write_json(out / "manifest.json", {})  # batch's own output folder (its ownership record and mark)
    mark_folder_output(out)
    (out / "recs" / "a").mkdir(parents=True)
    (out / "recs" / "a" / "notes.txt").write_text("mine")
    before = _listing(out)
    one_line_error(_batch(plan), f"{plan}: recordings[0] {workspace / 'recs' / 'a.mcap'}: {out / 'recs' / 'a'}: an "
                                "existing folder that kinfu did not write", "--force")
    assert _listing(out) == before and connects == []
    one_line_error(_batch(plan, "--force"), "connected to a cluster")


def test_empty_or_debris_only_folder_is_taken(workspace, connects):
    """An empty folder, or one holding only batch's lock and a killed run's temporaries, is no user's."""
    plan = _plan(workspace, ["fuse"], "fuse", "voxel-size = 0.04")
    out = workspace / "out"
    (out / "recs" / "a").mkdir(parents=True)
    (out / "recs" / "a" / ".pois.k3j_9a0z.part.json").write_text("{")
    one_line_error(_batch(plan), f"{out}: an existing folder")  # out holds recs/, a user's folder
    shutil.rmtree(out / "recs")
    (out / ".kinfu-batch.lock").write_text("kinfu batch lock pid 1\n")
    (out / "recs" / "a").mkdir(parents=True)
    (out / "recs" / "a" / ".fuse.k3j_9a0z.part").mkdir()
    write_json(out / "manifest.json", {})
    mark_folder_output(out)  # as a batch run leaves it
    one_line_error(_batch(plan), "connected to a cluster")
    assert len(connects) == 1


def test_output_folder_holding_an_input_is_refused_even_with_force(workspace, connects):
    plan = _plan(workspace, ["fuse"], "fuse", "voxel-size = 0.04")
    one_line_error(_batch(plan, "-o", workspace / "recs", "--force"), "contains the input")
    assert connects == [] and sorted(p.name for p in (workspace / "recs").iterdir()) == ["a.mcap", "ground_truth"]


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """A tiny synthetic tabletop recording (4 frames, 32 x 24)."""
    from kinfu_cli.sim.synth import synthesize

    base = tmp_path_factory.mktemp("folders_rec")
    synthesize(base / "synth", seed=0, width=32, height=24, frames=4, formats=("mcap",))
    return base / "synth" / "recording.mcap"


def _fuse_poi_plan(recording, tmp_path):
    """(plan, output folder, the recording's output folder) of a fuse + poi plan over a copy of `recording`."""
    (tmp_path / "recs").mkdir()
    shutil.copy(recording, tmp_path / "recs" / "a.mcap")
    plan = tmp_path / "plan.toml"
    plan.write_text('output = "out"\nstages = ["fuse", "poi"]\nrecordings = ["recs/a.mcap"]\n[options.fuse]\n'
                    'voxel-size = 0.04\n')
    return plan, tmp_path / "out", tmp_path / "out" / "recs" / "a"


@pytest.mark.slow
def test_force_keeps_user_files_and_a_rerun_resumes(recording, scheduler, tmp_path):
    """With --force batch writes beside the user's files, never over them; its folder is then its own, so the
    next run without --force is taken and skips what is current; a --force rerun keeps a user's file inside a
    folder output."""
    plan, out, rec_out = _fuse_poi_plan(recording, tmp_path)
    rec_out.mkdir(parents=True)
    for folder in (out, rec_out):
        (folder / "notes.txt").write_text(f"mine: {folder.name}")
    one_line_error(_batch(plan, "--scheduler", scheduler), f"{out}: an existing folder", "--force")
    res = _batch(plan, "--scheduler", scheduler, "--force")
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "manifest.json").read_text())
    assert {s: e["status"] for s, e in doc["recordings"][0]["stages"].items()} == {"fuse": "ok", "poi": "ok"}
    assert (rec_out / "fuse" / "volume.npz").is_file() and (rec_out / "pois.json").is_file()
    for folder in (out, rec_out):
        assert (folder / "notes.txt").read_text() == f"mine: {folder.name}"
    (rec_out / "fuse" / "mine.txt").write_text("inside")  # a user's file inside a folder kinfu wrote
    res = _batch(plan, "--scheduler", scheduler)  # batch's own folder now: taken, and nothing to redo
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "manifest.json").read_text())
    assert {s: e["status"] for s, e in doc["recordings"][0]["stages"].items()} == {"fuse": "skipped",
                                                                                   "poi": "skipped"}
    res = _batch(plan, "--scheduler", scheduler, "--force")  # everything redone: fuse/ replaced, mine.txt kept
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "manifest.json").read_text())
    assert {s: e["status"] for s, e in doc["recordings"][0]["stages"].items()} == {"fuse": "ok", "poi": "ok"}
    assert (rec_out / "fuse" / "mine.txt").read_text() == "inside"
    assert (out / "notes.txt").read_text() == "mine: out" and (rec_out / "notes.txt").read_text() == "mine: a"


def test_a_missing_file_option_is_refused_naming_the_plan_entry(workspace, connects):
    plan = _plan(workspace, BAD["nbv"][0], "nbv", 'candidates = "no_such_poses.json"')
    one_line_error(_batch(plan), f"{plan}: options.nbv.candidates: no_such_poses.json: no such file")
    assert connects == [] and not (workspace / "out").exists()


def test_file_options_are_read_beside_the_plan_and_fingerprinted(workspace, connects, monkeypatch, tmp_path_factory):
    """nbv's candidates / camera-info name files relative to the plan, as its recordings are, whatever the
    current folder; the file is one of the stage's inputs, so editing it makes the stage run again."""
    from kinfu_cli.batch.plan import load_plan
    from kinfu_cli.commands._batch_stages import batch_stages

    (workspace / "poses.json").write_text(json.dumps([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1], [0, 0, 0, 1]]]))
    plan = _plan(workspace, BAD["nbv"][0], "nbv", 'candidates = "poses.json"')
    monkeypatch.chdir(tmp_path_factory.mktemp("elsewhere"))
    one_line_error(_batch(plan), "connected to a cluster")  # the file was found: past every check
    table = batch_stages()
    rec = load_plan(plan, table, None, None).recordings[0]
    assert rec.stage_options("nbv")["candidates"] == str(workspace / "poses.json")
    assert ("--candidates", workspace / "poses.json") in table["nbv"].input_paths(rec)


def test_errors_name_options_as_the_plan_spells_them(workspace, connects):
    """A command's message that names several of its flags reads with the plan's option names (no dashes)."""
    plan = _plan(workspace, ["fuse", "segment"], "segment", "grasp = true\nno-superquadrics = true")
    line = one_line_error(_batch(plan), "segment: ")
    assert "grasp" in line and "no-superquadrics" in line and "--" not in line.split("segment: ", 1)[1]
    assert connects == []


@pytest.mark.slow
def test_redo_runs_every_stage_again_but_keeps_the_ownership_rule(recording, scheduler, tmp_path):
    """--redo recomputes what is current (fuse and poi run again, not skipped) without --force's licence: a
    user's file where a stage writes is still refused."""
    plan, out, rec_out = _fuse_poi_plan(recording, tmp_path)

    def statuses():
        doc = json.loads((out / "manifest.json").read_text())
        return {s: e["status"] for s, e in doc["recordings"][0]["stages"].items()}
    assert _batch(plan, "--scheduler", scheduler).exit_code == 0
    assert statuses() == {"fuse": "ok", "poi": "ok"}
    assert _batch(plan, "--scheduler", scheduler).exit_code == 0
    assert statuses() == {"fuse": "skipped", "poi": "skipped"}
    assert _batch(plan, "--scheduler", scheduler, "--redo").exit_code == 0
    assert statuses() == {"fuse": "ok", "poi": "ok"}
    (rec_out / "pois.json").unlink()
    (rec_out / "pois.json").write_text("mine")  # a user's file where poi writes
    one_line_error(_batch(plan, "--scheduler", scheduler, "--redo"), "pois.json", "--force")
    assert (rec_out / "pois.json").read_text() == "mine"


@pytest.mark.parametrize("where", ["plan", "option"])
def test_a_batch_folder_named_like_a_file_is_refused(where, workspace, connects):
    """output = "runs.json" (or -o runs.json) before any work, as every command's folder outputs
    (output_path.output_kind_problem); the plan already checks its viewer file's name."""
    plan = _plan(workspace, ["poi"], "poi", "max-components = 3")
    if where == "plan":
        plan.write_text(plan.read_text().replace('output = "out"', 'output = "runs.json"'))
        one_line_error(_batch(plan), f"{plan}: output: {workspace / 'runs.json'} names a .json file; this output "
                                     f"is a folder")
    else:
        one_line_error(_batch(plan, "-o", workspace / "runs.json"), "--output:", "names a .json file")
    assert connects == [] and not (workspace / "out").exists() and not (workspace / "runs.json").exists()
