"""Options given in a mode where they have no effect were ignored without a word (`fuse --max-lost 5% --pose forced`,
`segment --t-lccp 0.1 --method flood-fill`, `poi --zvc-r1 0.2 --algorithm gmm-as`). Each command now checks its
INAPPLICABLE rules with the shared commands._options.check_inapplicable: a `kinfu: warning:` line naming every
such option given and the mode, and the run goes on (exit 0); the combinations kinfu refused before (`nbv --mode
objects` with the POI mode's options, segment's --grasp-* without --grasp, eval segment's sweep options without
--sweep) stay one `kinfu: error:` line, exit 2, before any work. "Given" is click's parameter source: an option given at its default value counts. Fixed-count number
options ('x,y,z') say an empty item as the comma-list options do."""

from __future__ import annotations

import importlib
import json
from types import SimpleNamespace

import click
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import COMMANDS, cli
from kinfu_cli.commands._batch_stages import check_stage
from kinfu_cli.commands._options import check_inapplicable
from kinfu_cli.core.errors import ConfigError
from tests.conftest import one_line_error

# (command line, the options named, the mode named, the same line made applicable). Inputs need not exist: the
# check comes before anything is read. Values at the option's default are marked "# default".
WARNED = [
    (["fuse", "{rec}", "-o", "{out}", "--no-color", "--color", "mean"], ["--color"], "with --no-color",
     ["fuse", "{rec}", "-o", "{out}", "--color", "mean"]),
    (["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--poi-threshold", "2", "--merge-distance", "0"],
     ["--poi-threshold", "--merge-distance"], "with --algorithm zvc",
     ["poi", "{rec}", "-o", "{out}.json", "--algorithm", "gmm-as", "--poi-threshold", "2", "--merge-distance", "0"]),
    (["poi", "{rec}", "-o", "{out}.json", "--zvc-r1", "0.2", "--zvc-rule", "ratio"], ["--zvc-rule", "--zvc-r1"],
     "with --algorithm gmm-as",
     ["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--zvc-r1", "0.2", "--zvc-rule", "ratio"]),
    (["poi", "{rec}", "-o", "{out}.json", "--literal", "--saliency", "precision"], ["--saliency"], "with --literal",
     ["poi", "{rec}", "-o", "{out}.json", "--saliency", "precision"]),
    (["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--zvc-rule", "ratio", "--zvc-relative", "0.3"],
     ["--zvc-relative"], "with --zvc-rule ratio",
     ["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--zvc-rule", "relative", "--zvc-relative", "0.3"]),
    (["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--zvc-threshold", "1.5", "--zvc-relative", "0.28"],
     ["--zvc-relative"], "with --zvc-threshold (ZVC's ratio rule)",  # 0.28: default
     ["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--zvc-relative", "0.28"]),
    (["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--zvc-rule", "relative", "--zvc-threshold", "1.5"],
     ["--zvc-threshold"], "with --zvc-rule relative",
     ["poi", "{rec}", "-o", "{out}.json", "--algorithm", "zvc", "--zvc-rule", "ratio", "--zvc-threshold", "1.5"]),
    (["eval", "poi", "{tmp}", "--loo", "--speed", "1", "--seed", "0"], ["--speed", "--seed"], "with --loo",  # defaults
     ["eval", "poi", "{tmp}", "--speed", "1", "--seed", "0"]),
    (["eval", "poi", "{tmp}", "--algorithm", "gmm-as", "--zvc-half-width", "4"], ["--zvc-half-width"],
     "with --algorithm gmm-as", ["eval", "poi", "{tmp}", "--algorithm", "both", "--zvc-half-width", "4"]),
    (["segment", "{vol}", "-o", "{out}", "--method", "flood-fill", "--t-lccp", "0.1", "--concavity-tolerance", "40",
      "--seed-resolution", "0.04"], ["--seed-resolution", "--t-lccp", "--concavity-tolerance"],
     "with --method flood-fill",  # 40, 0.04: defaults
     ["segment", "{vol}", "-o", "{out}", "--method", "lccp", "--t-lccp", "0.1", "--concavity-tolerance", "40",
      "--seed-resolution", "0.04"]),
    (["segment", "{vol}", "-o", "{out}", "--t-ff", "0.5"], ["--t-ff"], "with --method lccp",  # default value
     ["segment", "{vol}", "-o", "{out}", "--method", "flood-fill", "--t-ff", "0.5"]),
    (["segment", "{vol}", "-o", "{out}", "--no-color", "--plane-color-margin", "0.02", "--color-importance", "2"],
     ["--color-importance", "--plane-color-margin"], "with --no-color",
     ["segment", "{vol}", "-o", "{out}", "--plane-color-margin", "0.02", "--color-importance", "2"]),
    (["segment", "{vol}", "-o", "{out}", "--color-distance", "rgb"], ["--color-distance"],
     "with --method lccp without --t-lccp", ["segment", "{vol}", "-o", "{out}", "--color-distance", "rgb",
                                             "--t-lccp", "0.2"]),
    (["segment", "{vol}", "-o", "{out}", "--no-superquadrics", "--sq-cost", "radial", "--no-shape-prior"],
     ["--sq-cost", "--shape-prior/--no-shape-prior"], "with --no-superquadrics",
     ["segment", "{vol}", "-o", "{out}", "--sq-cost", "radial", "--no-shape-prior"]),
    (["segment", "{vol}", "-o", "{out}", "--msq-height", "3", "--msq-cut", "barycentre"],
     ["--msq-height", "--msq-cut"], "without --multi-sq",  # 3: default
     ["segment", "{vol}", "-o", "{out}", "--multi-sq", "--msq-height", "3", "--msq-cut", "barycentre"]),
    (["segment", "{vol}", "-o", "{out}", "--up", "none", "--up-tolerance", "10"], ["--up-tolerance"], "with --up none",
     ["segment", "{vol}", "-o", "{out}", "--up", "0,0,1", "--up-tolerance", "10"]),
    (["nbv", "{vol}", "--pois", "{tmp}/p.json", "--candidates", "{tmp}/c.json", "-o", "{out}.json", "--radius", "0.8",
      "--lat-max", "90"], ["--radius", "--lat-max"], "with --candidates",  # both defaults
     ["nbv", "{vol}", "--pois", "{tmp}/p.json", "-o", "{out}.json", "--radius", "0.8", "--lat-max", "90"]),
    (["grasp", "{tmp}/segments.json", "-o", "{out}.json", "--hand", "right", "--workspace-left", "0,1,0,1,0,1"],
     ["--workspace-left"], "with --hand right",
     ["grasp", "{tmp}/segments.json", "-o", "{out}.json", "--workspace-left", "0,1,0,1,0,1"]),
    (["grasp", "{tmp}/segments.json", "-o", "{out}.json", "--hand", "left", "--workspace-right", "0,1,0,1,0,1"],
     ["--workspace-right"], "with --hand left",
     ["grasp", "{tmp}/segments.json", "-o", "{out}.json", "--hand", "right", "--workspace-right", "0,1,0,1,0,1"]),
    (["eval", "localize", "-o", "{out}.json", "--recognition-trials", "0", "--recognition-points", "170"],
     ["--recognition-points"], "with --recognition-trials 0",  # 170: default
     ["eval", "localize", "-o", "{out}.json", "--recognition-points", "170"]),
    (["eval", "localize", "-o", "{out}.json", "--methods", "scaling_series,ransac_icp", "--recognition-trials", "0",
      "--particles", "700", "--paper-weights"], ["--particles", "--paper-weights"],
     "with --methods without mupf and --recognition-trials 0",
     ["eval", "localize", "-o", "{out}.json", "--methods", "scaling_series,ransac_icp", "--particles", "700",
      "--paper-weights"]),
    (["eval", "nbv", "{tmp}", "-o", "{out}.json", "--strategy", "objects,standard", "--mode", "kfovp", "--inc-th",
      "5"], ["--mode", "--inc-th"], "with --strategy objects,standard",  # kfovp: default
     ["eval", "nbv", "{tmp}", "-o", "{out}.json", "--strategy", "poi", "--mode", "kfovp", "--inc-th", "5"]),
    (["eval", "nbv", "{tmp}", "-o", "{out}.json", "--strategy", "poi,random", "--scan-frames", "8"], ["--scan-frames"],
     "with --strategy poi,random", ["eval", "nbv", "{tmp}", "-o", "{out}.json", "--strategy", "objects",
                                    "--scan-frames", "8"]),
    (["synth", "-o", "{out}", "--scene", "room", "--scenario", "place", "--hand-rate", "100"],
     ["--scenario", "--hand-rate"], "with --scene room",  # 100: default
     ["synth", "-o", "{out}", "--scenario", "place", "--hand-rate", "100"]),
    (["synth", "-o", "{out}", "--scene", "household", "--n-objects", "4"], ["--n-objects"], "with --scene household",
     ["synth", "-o", "{out}", "--scene", "tabletop", "--n-objects", "4"]),
    (["synth", "-o", "{out}", "--world", "z-up"], ["--world"], "with --scene tabletop",  # default value
     ["synth", "-o", "{out}", "--scene", "room", "--world", "z-up"]),
    (["synth", "-o", "{out}", "--color-format", "png", "--jpeg-quality", "90"], ["--jpeg-quality"],
     "with --color-format png", ["synth", "-o", "{out}", "--jpeg-quality", "90"]),
    (["import", "{tmp}", "-o", "{out}", "--no-compress"], ["--no-compress"], "with a ROS 2 bag folder as --out",
     ["import", "{tmp}", "-o", "{out}.mcap", "--no-compress"]),
    (["info", "{rec}", "--every", "1", "--pose-source", "tf"], ["--pose-source", "--every"], "without --frames",
     ["info", "{rec}", "--frames", "--every", "1", "--pose-source", "tf"]),
]


# the combinations kinfu refused before the rules were shared (their own wordings are tested beside their commands)
REFUSED = [
    (["nbv", "{vol}", "--mode", "objects", "-o", "{out}.json", "--roll-step", "45"], ["--roll-step"],
     "with --mode objects", ["nbv", "{vol}", "--pois", "{tmp}/p.json", "-o", "{out}.json", "--roll-step", "45"]),
]
CASES = WARNED + REFUSED


def _args(args: list[str], tmp_path) -> list[str]:
    return [a.format(tmp=tmp_path, rec=tmp_path / "rec.mcap", vol=tmp_path / "volume.npz", out=tmp_path / "out")
            for a in args]


def _leaf(args: list[str]) -> tuple[object, list[str]]:
    """The command module of a command line, and its arguments after the command's name."""
    target = COMMANDS[args[0]]
    if isinstance(target, dict):
        return importlib.import_module(f"kinfu_cli.commands.{target[args[1]]}"), args[2:]
    return importlib.import_module(f"kinfu_cli.commands.{target}"), args[1:]


@pytest.mark.parametrize("args, flags, mode, _", WARNED, ids=[" ".join(c[0][:3] + c[1]) for c in WARNED])
def test_an_option_without_effect_in_the_mode_given_is_warned_about(tmp_path, capsys, args, flags, mode, _):
    """The check each command runs first: one warning line naming the options given and the mode; the run goes
    on (the real runs below)."""
    module, leaf = _leaf(_args(args, tmp_path))
    check_inapplicable(module.command.make_context("kinfu", leaf), module.INAPPLICABLE)
    has = "has" if len(flags) == 1 else "have"
    assert capsys.readouterr().err == f"kinfu: warning: {', '.join(flags)} {has} no effect {mode} (ignored)\n"


@pytest.mark.parametrize("args, flags, mode, _", REFUSED, ids=[" ".join(c[0][:3] + c[1]) for c in REFUSED])
def test_the_combinations_refused_before_stay_refused(tmp_path, args, flags, mode, _):
    res = CliRunner().invoke(cli, _args(args, tmp_path))
    line = one_line_error(res)
    has = "has" if len(flags) == 1 else "have"
    assert line.startswith(f"kinfu: error: {', '.join(flags)}: {has} no effect {mode}; "), line
    assert not list(tmp_path.glob("out*"))  # nothing written


def test_a_warned_option_does_not_stop_the_run(sample_dir, tmp_path):
    """segment --t-ff with LCCP (the default method): the warning, then the segmentation, as without --t-ff."""
    vol = tmp_path / "f"
    res = CliRunner().invoke(cli, ["fuse", str(sample_dir / "recording.mcap"), "-o", str(vol), "--end", "1",
                                   "--resolution", "64", "--quiet"])
    assert res.exit_code == 0, res.output
    out = tmp_path / "s"
    res = CliRunner().invoke(cli, ["segment", str(vol / "volume.npz"), "-o", str(out), "--t-ff", "0.3",
                                   "--no-superquadrics", "--quiet"])
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: --t-ff has no effect with --method lccp (ignored)" in res.output.splitlines()
    assert json.loads((out / "segments.json").read_text())["options"]["segmentation"]["method"] == "lccp"


@pytest.mark.parametrize("_, flags, mode, applicable", CASES, ids=[" ".join(c[0][:3] + c[1]) for c in CASES])
def test_the_same_options_in_their_own_mode_pass_the_check(tmp_path, _, flags, mode, applicable):
    """The applicable combination passes the very check the command runs first (and batch runs on a plan)."""
    module, args = _leaf(_args(applicable, tmp_path))
    ctx = module.command.make_context("kinfu", args)
    for flag in flags:  # the options are still given there
        name = next(p.name for p in module.command.params if flag.split("/")[0] in p.opts)
        assert ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE
    check_inapplicable(ctx, module.INAPPLICABLE)  # neither an error nor a warning (capsys below)


def test_the_applicable_combinations_print_no_warning(tmp_path, capsys):
    for *_, applicable in CASES:
        module, args = _leaf(_args(applicable, tmp_path))
        check_inapplicable(module.command.make_context("kinfu", args), module.INAPPLICABLE)
    assert capsys.readouterr().err == ""


def test_every_rule_names_options_of_its_command_and_reads_its_parameters(tmp_path):
    """A misspelt option in a rule would never be caught; a mode reading a missing parameter would fail."""
    seen = 0
    for name, target in COMMANDS.items():
        for module_name in (target.values() if isinstance(target, dict) else [target]):
            module = importlib.import_module(f"kinfu_cli.commands.{module_name}")
            flags = {o[2:] for p in module.command.params for o in (*p.opts, *p.secondary_opts) if o.startswith("--")}
            defaults = {p.name: p.get_default(click.Context(module.command)) for p in module.command.params}
            defaults.update(out=str(tmp_path / "o"), size="auto", up="auto", strategies="poi", methods="mupf")
            for rule in getattr(module, "INAPPLICABLE", ()):
                assert set(rule.options) <= flags, (module_name, set(rule.options) - flags)
                rule.mode(defaults)
                seen += 1
    assert seen >= 25


def test_fuse_tracking_options_with_forced_poses_warn_and_fuse(sample_dir, tmp_path):
    """--max-lost and --icp (at its default, given) with --pose forced: a warning naming both, the run goes on."""
    out = tmp_path / "f"
    res = CliRunner().invoke(cli, ["fuse", str(sample_dir / "recording.mcap"), "-o", str(out), "--pose", "forced",
                                   "--max-lost", "5%", "--icp", "projective", "--end", "1", "--resolution", "32",
                                   "--quiet"])
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: --max-lost, --icp have no effect with --pose forced (ignored)" in res.output.splitlines()
    assert json.loads((out / "report.json").read_text())["pose_mode"] == "forced"


def test_fuse_tracking_options_with_poses_the_recording_gave_warn_in_the_report(sample_dir, tmp_path):
    """No --pose, and the sample's TF has the camera: fusion chooses forced poses once it has read the recording,
    so --max-lost was unused without a word; now report.json's warnings say it, and stderr."""
    out = tmp_path / "f"
    res = CliRunner().invoke(cli, ["fuse", str(sample_dir / "recording.mcap"), "-o", str(out), "--max-lost", "5%",
                                   "--end", "1", "--resolution", "32", "--quiet"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    assert report["pose_mode"] == "forced"
    said = [w for w in report["warnings"] if w.startswith("--max-lost has no effect: the recording gave")]
    assert len(said) == 1 and f"kinfu: warning: {said[0]}" in res.output.splitlines()
    res = CliRunner().invoke(cli, ["fuse", str(sample_dir / "recording.mcap"), "-o", str(tmp_path / "g"), "--end",
                                   "1", "--resolution", "32", "--quiet"])  # not given: nothing said
    assert not [w for w in json.loads((tmp_path / "g" / "report.json").read_text())["warnings"] if "no effect" in w]


def test_fuse_tracking_options_without_a_pose_mode_are_not_warned_about(sample_dir, tmp_path):
    """No --pose: the mode follows the recording (icp without TF), so --max-lost may apply."""
    module, args = _leaf(["fuse", str(sample_dir / "recording.mcap"), "-o", str(tmp_path / "f"), "--max-lost", "5%",
                          "--pose", "icp"])
    check_inapplicable(module.command.make_context("kinfu", args), module.INAPPLICABLE)
    module, args = _leaf(["fuse", "r.mcap", "-o", str(tmp_path / "f"), "--max-lost", "5%"])
    check_inapplicable(module.command.make_context("kinfu", args), module.INAPPLICABLE)


@pytest.mark.parametrize("extra, said", [
    (["--pose", "forced"], "kinfu: warning: --photometric-weight has no effect with --pose forced (ignored)\n"),
    (["--pose", "icp", "--icp", "open3d"],
     "kinfu: warning: --photometric-weight has no effect with --icp open3d (ignored)\n"),
    (["--pose", "icp"], "")])
def test_fuse_photometric_weight_where_no_projective_icp_runs_is_a_warning(tmp_path, capsys, extra, said):
    """The colour term is projective ICP's: with poses given (forced) or open3d's ICP it does nothing."""
    module, args = _leaf(["fuse", "r.mcap", "-o", str(tmp_path / "f"), "--photometric-weight", "0.1", *extra])
    check_inapplicable(module.command.make_context("kinfu", args), module.INAPPLICABLE)
    assert capsys.readouterr().err == said


@pytest.mark.parametrize("extra, mode", [(["--size", "2"], "with --size 2"), (["--init", "v.npz"], "with --init")])
def test_fuse_max_memory_with_a_given_grid_is_a_warning(tmp_path, capsys, extra, mode):
    module, args = _leaf(["fuse", "r.mcap", "-o", str(tmp_path / "f"), "--max-memory", "2", *extra])
    check_inapplicable(module.command.make_context("kinfu", args), module.INAPPLICABLE)
    assert capsys.readouterr().err == f"kinfu: warning: --max-memory has no effect {mode} (ignored)\n"


def test_diff_match_radius_without_pois_warns_and_compares(tmp_path):
    from kinfu_cli.core.grid import TernaryGrid, save_ternary
    import numpy as np

    labels = np.zeros((8, 8, 8), np.int8)
    labels[2:4, 2:4, 2:4] = 1
    save_ternary(tmp_path / "a.npz", TernaryGrid(labels, (0, 0, 0), 0.05))
    labels[2:4, 2:4, 2:4] = -1
    save_ternary(tmp_path / "b.npz", TernaryGrid(labels, (0, 0, 0), 0.05))
    out = tmp_path / "d"
    res = CliRunner().invoke(cli, ["diff", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "-o", str(out),
                                   "--match-radius", "0.2", "--quiet"])  # 0.2: the default
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: --match-radius has no effect without --pois (ignored)" in res.output.splitlines()
    assert (out / "changes.json").is_file()


def _plan_recording(tmp_path) -> SimpleNamespace:
    return SimpleNamespace(path=tmp_path / "rec.mcap", output=tmp_path / "out", stages=("fuse", "diff"),
                           links={"before": tmp_path / "before.npz"})


def test_batch_refuses_a_plan_option_the_stage_command_refuses(tmp_path):
    with pytest.raises(ConfigError, match=r"^grasp-hand: needs grasp \(no grasps are planned without it\)$"):
        check_stage("segment", _plan_recording(tmp_path), {"grasp-hand": "left"})
    check_stage("segment", _plan_recording(tmp_path), {"grasp-hand": "left", "grasp": True})


def test_batch_plan_options_that_only_warn_do_not_fail_the_check(tmp_path):
    """A plan's common options for recordings of either mode: diff without --pois (batch gives it only to the
    recordings that run poi), fuse's tracking options with a recording fused with forced poses."""
    rec = _plan_recording(tmp_path)
    check_stage("diff", rec, {"match-radius": 0.1})
    check_stage("segment", rec, {"t-ff": 0.3})
    check_stage("fuse", rec, {"pose": "forced", "max-lost": "20%", "icp": "open3d", "size": 2, "resolution": 32,
                              "max-memory": 1})


@pytest.mark.parametrize("args, option", [
    (["fuse", "{rec}", "-o", "{out}", "--origin", "1,,2"], "--origin"),
    (["fuse", "{rec}", "-o", "{out}", "--size", "1,1,"], "--size"),
    (["fuse", "{rec}", "-o", "{out}", "--resolution", "64,,64,64"], "--resolution"),
    (["fuse", "{rec}", "-o", "{out}", "--clear-sphere", "0,0,,0.1"], "--clear-sphere"),
    (["fuse", "{rec}", "-o", "{out}", "--up", "0,,1"], "--up"),
    (["fuse", "{rec}", "-o", "{out}", "--intrinsics", "525,,319.5,239.5"], "--intrinsics"),
    (["segment", "{vol}", "-o", "{out}", "--up", ",0,1"], "--up"),
    (["segment", "{vol}", "-o", "{out}", "--sq-exponent-bounds", "0.1,"], "--sq-exponent-bounds"),
    (["nbv", "{vol}", "--pois", "{tmp}/p.json", "-o", "{out}.json", "--up", "0,0,,1"], "--up"),
    (["grasp", "{tmp}/s.json", "-o", "{out}.json", "--hand-size", "0.03,,0.05"], "--hand-size"),
    (["grasp", "{tmp}/s.json", "-o", "{out}.json", "--workspace-right", "0,1,,1,0,1"], "--workspace-right"),
    (["poi", "{rec}", "-o", "{out}.json", "--workspace", "0,0,0,1,1,,1"], "--workspace"),
    (["localize", "{tmp}/m.ply", "{tmp}/p.txt", "-o", "{out}.json", "--prior", "0,0,0,,0,0"], "--prior"),
    (["import", "{tmp}/frames", "-o", "{out}.mcap", "--up", "0,0,1,"], "--up"),
    (["import", "{tmp}/frames", "-o", "{out}.mcap", "--intrinsics", "525,525,,239.5"], "--intrinsics"),
])
def test_an_empty_item_of_a_fixed_count_option_reads_as_the_list_options_say_it(tmp_path, args, option):
    """'1,,2' was "expected 3 comma-separated finite numbers" (or skipped: poi --workspace read 0,0,0,1,1,,1 as six
    numbers); now the comma-list options' words: the option, its value, an empty item."""
    (tmp_path / "m.ply").write_text("ply\n")
    (tmp_path / "p.txt").write_text("0 0 0\n")
    args = _args(args, tmp_path)
    value = args[args.index(option) + 1]
    res = CliRunner().invoke(cli, args + ["--quiet"])
    line = one_line_error(res, option)
    assert line == f"kinfu: error: {option} {value!r}: an empty item; expected comma-separated values without gaps"
    assert not list(tmp_path.glob("out*"))


@pytest.mark.parametrize("args, said", [
    (["fuse", "{rec}", "-o", "{out}", "--origin", "1,2"], "--origin: expected 3 comma-separated finite numbers"),
    (["fuse", "{rec}", "-o", "{out}", "--origin", "1,nan,2"], "--origin: expected 3 comma-separated finite numbers"),
    (["grasp", "{tmp}/s.json", "-o", "{out}.json", "--hand-size", "0.03,0.05"],
     "--hand-size: expected 3 comma-separated finite numbers"),
    (["segment", "{vol}", "-o", "{out}", "--sq-exponent-bounds", "0.1,0.5,1"],
     "--sq-exponent-bounds: expected two numbers 'lo,hi'"),
])
def test_a_wrong_count_still_says_the_count(tmp_path, args, said):
    res = CliRunner().invoke(cli, _args(args, tmp_path) + ["--quiet"])
    one_line_error(res, said)
