"""`kinfu batch` refuses option values out of the library's ranges before any work: each stage's command builds
and validates its parameter objects without reading an input. Before, such values passed the check (click parses
only the type), failed inside the Dask task, and the recording was marked failed (exit 1)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.commands._batch_stages import _COMMANDS
from kinfu_cli.core.errors import KinfuError

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
    ("poi", 'workspace = "1,2"', "poi: workspace: expected six numbers"),
    ("nbv", "clearance = -1", "nbv: clearance: expected a finite number >= 0"),
    ("nbv", "min-range = 9", "nbv: min-range/max-range: expected 0 <= min < max"),
    ("nbv", 'candidates = "no_such_poses.json"', "nbv: no_such_poses.json: no such candidate file"),
    ("segment", 'sq-exponent-bounds = "3,1"', "segment: sq-exponent-bounds: expected 0 < lo < hi <= 2"),
    ("diff", "match-radius = 0", "diff: match-radius: expected a positive distance"),
    ("eval-nbv", "lon-step = 0", "eval-nbv: lon-step: expected a step in (0, 360]"),
    ("eval-segment", "t-eval = 0", "eval-segment: t-eval: expected a number in (0, 1]"),
]


class Connected(KinfuError):
    """Raised by the spy standing in for the Dask connection: the run got past every check."""


@pytest.fixture
def connects(monkeypatch) -> list:
    """Calls of batch's cluster connection (none may happen for bad input); a call ends the run with exit 2."""
    calls: list = []

    def spy(*args, **kwargs):
        calls.append(args)
        raise Connected("connected to a cluster")

    monkeypatch.setattr("kinfu_cli.commands.batch.connect", spy)
    return calls


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
