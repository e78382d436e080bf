"""`kinfu batch`: one run at a time per output folder (a lock), and the inputs of the eval-nbv / eval-segment stages
checked before any work. The stages themselves run in test_batch_diff_eval.py."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.batch.lock import LOCK_NAME, batch_lock
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError


def _batch(*args):
    return CliRunner().invoke(cli, ["batch", *map(str, args), "--quiet"], catch_exceptions=False)


@pytest.fixture
def lab(sample_dir, tmp_path) -> Path:
    """rec/recording.mcap (the sample) with a ground_truth/ holding only changes.json (no labels, no poses)."""
    (tmp_path / "rec" / "ground_truth").mkdir(parents=True)
    (tmp_path / "rec" / "recording.mcap").symlink_to(sample_dir / "recording.mcap")
    (tmp_path / "rec" / "ground_truth" / "changes.json").symlink_to(sample_dir / "ground_truth" / "changes.json")
    return tmp_path


def _plan(lab: Path, stages: str, options: str = "") -> Path:
    plan = lab / "plan.toml"
    plan.write_text(f'output = "out"\nstages = [{stages}]\nrecordings = ["rec/recording.mcap"]\n{options}')
    return plan


def test_a_second_run_on_the_folder_fails_naming_the_lock(lab):
    plan = _plan(lab, '"poi"')
    out = lab / "out"
    with batch_lock(out) as held:
        assert held == out / LOCK_NAME
        line = one_line_error(_batch(plan), str(held), "another kinfu batch is writing to")
        assert "pid" in line
        assert not (out / "manifest.json").exists() and held.exists()
        with pytest.raises(ConfigError, match=LOCK_NAME):  # also from the library, for any second holder
            with batch_lock(out):
                pass
    with batch_lock(out):  # released when the first run ends (or dies: the kernel drops it)
        pass


def test_the_lock_leaves_no_trace_when_nothing_ran_and_keeps_a_foreign_file(lab):
    plan = _plan(lab, '"poi"', "[options.poi]\nbogus = 1\n")  # refused by the checks, which run under the lock
    out = lab / "out"
    one_line_error(_batch(plan), "unknown option 'bogus'")
    assert not out.exists()  # the folder the lock created went with it
    plan = _plan(lab, '"poi"')
    out.mkdir()
    (out / LOCK_NAME).write_text("my notes\n")
    one_line_error(_batch(plan), LOCK_NAME, "not written by kinfu")
    assert (out / LOCK_NAME).read_text() == "my notes\n"


@pytest.mark.parametrize("stages, options, needles", [
    ('"fuse", "segment", "eval-segment"', "", ["eval-segment", "labels.npz"]),
    ('"eval-nbv"', "", ["eval-nbv", "camera_poses.txt"]),
    ('"fuse", "segment", "eval-segment"', "[options.eval-segment]\nsweep = true\n",
     ["eval-segment", "'sweep'", "--sweep"]),
    ('"eval-nbv"', "[options.eval-nbv]\nworkers = 2\n", ["eval-nbv", "'workers' is set by batch"]),
])
def test_missing_eval_inputs_and_bad_options_are_one_line_before_any_work(lab, stages, options, needles):
    plan = _plan(lab, stages, options)
    one_line_error(_batch(plan), str(plan), "recordings[0]", *needles)
    assert not (lab / "out").exists()


def test_eval_stages_are_listed_with_their_needs(lab):
    plan = _plan(lab, '"fuse", "eval-segment"')
    one_line_error(_batch(plan), "eval-segment needs segment")


def test_a_run_refused_in_a_users_folder_leaves_nothing_there(lab):
    out = lab / "out"
    out.mkdir()
    (out / "manifest.json").write_text("{}")  # the user's, not kinfu's
    one_line_error(_batch(_plan(lab, '"poi"')), "manifest.json", "kinfu did not write")
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json"]  # no lock file left behind
    assert (out / "manifest.json").read_text() == "{}"
