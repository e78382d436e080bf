"""`kinfu eval segment` refuses the options that only mean something with --sweep when it scores SEGMENTS (they
were ignored silently), and batch's eval-segment stage refuses the same set."""

from __future__ import annotations

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.commands._options import SWEEP_ONLY_OPTIONS
from kinfu_cli.commands.eval_segment import command

# a value for each sweep-only option: its default where it has one (given counts, not differing from the default)
_VALUES = {"sweep-parameter": ["t_lccp"], "sweep-values": ["0.1,0.2"], "color-distance": ["chroma"],
           "method": ["lccp"], "color": ["mean,mode"], "photometric": [], "scene": ["objects"],
           "scenes": ["0,1,2"], "resolution": ["160"]}


def test_the_sweep_only_set_names_real_options():
    flags = {o[2:] for p in command.params for o in p.opts if o.startswith("--")}
    assert SWEEP_ONLY_OPTIONS <= flags and set(_VALUES) == SWEEP_ONLY_OPTIONS


@pytest.mark.parametrize("key", sorted(SWEEP_ONLY_OPTIONS))
def test_a_sweep_only_option_without_sweep_is_a_one_line_error(tmp_path, key):
    out = tmp_path / "eval.json"
    r = CliRunner().invoke(cli, ["eval", "segment", str(tmp_path / "segments"), "--ground-truth",
                                 str(tmp_path / "labels.npz"), f"--{key}", *_VALUES[key], "-o", str(out)])
    one_line_error(r, f"--{key}", "needs --sweep")
    assert not out.exists()


def test_no_photometric_and_several_options_are_all_named(tmp_path):
    r = CliRunner().invoke(cli, ["eval", "segment", "--no-photometric", "--scenes", "4", "--t-eval", "0.03"])
    line = one_line_error(r, "--photometric/--no-photometric", "--scenes", "needs --sweep")
    assert "--t-eval" not in line  # scored without --sweep too


def test_without_sweep_only_options_the_usual_checks_run(tmp_path):
    r = CliRunner().invoke(cli, ["eval", "segment", "--t-eval", "0.03", "--matching", "greedy"])
    one_line_error(r, "expected SEGMENTS")


def test_batch_refuses_color_distance_for_the_eval_segment_stage(sample_dir, tmp_path):
    (tmp_path / "rec" / "ground_truth").mkdir(parents=True)
    (tmp_path / "rec" / "recording.mcap").symlink_to(sample_dir / "recording.mcap")
    (tmp_path / "rec" / "ground_truth" / "changes.json").symlink_to(sample_dir / "ground_truth" / "changes.json")
    plan = tmp_path / "plan.toml"
    plan.write_text('output = "out"\nstages = ["fuse", "segment", "eval-segment"]\nrecordings = ["rec/recording.mcap"]\n'
                    '[options.eval-segment]\ncolor-distance = "rgb"\n')
    r = CliRunner().invoke(cli, ["batch", str(plan), "--quiet"], catch_exceptions=False)
    one_line_error(r, "'color-distance'", "--sweep")
    assert not (tmp_path / "out").exists()
