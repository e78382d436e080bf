"""The stages of `kinfu batch`: each is the single command itself, run in-process on a Dask worker.

Running the click command (not a re-implementation over its driver) keeps one parser, one set of defaults
and one output writer per stage: a batch stage accepts exactly the command's options (flag names without
the dashes, in the plan) and writes exactly the files the command writes, with its atomic folders and
ownership records. The options are parsed by click before any work (`check`), so a bad value is a one-line
error naming the plan entry. Options that batch itself sets (outputs, inputs of other stages, --json,
--quiet, --force) are refused.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
from functools import partial
from pathlib import Path

import click

from kinfu_cli.batch.stages import RECORDING, StageRun, StageSpec
from kinfu_cli.commands._options import SWEEP_ONLY_OPTIONS, check_inapplicable, option_flags
from kinfu_cli.core.errors import ConfigError, KinfuError

# eval segment --sweep makes its own scenes: not a stage of a recording
_SWEEP_OPTIONS = {"sweep", *SWEEP_ONLY_OPTIONS}
# stage -> (module of the command, options batch sets itself, options taking an output file whose `true` in the
# plan means "this file in the recording's output folder"). A viewer output option (a file) goes in the last.
_COMMANDS = {
    "fuse": ("fuse", {"output", "json", "quiet", "force", "init", "clear-pois"}, {"viz": "fuse.mcap"}),
    "poi": ("poi", {"output", "json", "quiet", "force"}, {"plot": "pois.png", "viz": "pois.mcap"}),
    "nbv": ("nbv", {"output", "json", "quiet", "force", "pois", "mode"}, {"plot": "views.png", "viz": "views.mcap"}),
    "segment": ("segment", {"output", "json", "quiet", "force"}, {"viz": "segment.mcap"}),
    "diff": ("diff", {"output", "json", "quiet", "force", "pois"}, {}),
    "eval-fusion": ("eval_fusion", {"output", "json", "quiet", "force", "ground-truth"},
                    {"error-mesh": "eval_fusion_error.ply"}),
    # the trials run inside the stage's task: batch's cluster is the engine, no nested one
    "eval-nbv": ("eval_nbv", {"output", "json", "quiet", "force", "workers", "scheduler"}, {"plot": "eval_nbv.png"}),
    "eval-segment": ("eval_segment", {"output", "json", "quiet", "force", "ground-truth", *_SWEEP_OPTIONS},
                     {"plot": "eval_segment.png"}),
}
#: the viewer file each stage writes with `viz = true` (the combined viewer file is made from these)
VIEWER_FILES = {stage: files["viz"] for stage, (_, _, files) in _COMMANDS.items() if "viz" in files}


def _module(stage: str):
    import importlib

    return importlib.import_module(f"kinfu_cli.commands.{_COMMANDS[stage][0]}")


def _command(stage: str) -> click.Command:
    return _module(stage).command


def _base_args(stage: str, rec) -> list[str]:
    """The positional inputs and the outputs of the stage's command for one plan recording."""
    outdir = rec.output
    volume = str(outdir / "fuse" / "volume.npz")
    if stage == "fuse":
        return [str(rec.path), "-o", str(outdir / "fuse")]
    if stage == "poi":
        return [str(rec.path), "-o", str(outdir / "pois.json")]
    if stage == "nbv":
        return [volume, "--pois", str(outdir / "pois.json"), "-o", str(outdir / "views.json")]
    if stage == "segment":
        return [volume, "-o", str(outdir / "segment")]
    if stage == "diff":  # POIs scored against the changes when the recording has them
        pois = ["--pois", str(outdir / "pois.json")] if "poi" in rec.stages else []
        return [str(rec.links["before"]), volume, "-o", str(outdir / "diff"), *pois]
    if stage == "eval-fusion":
        return [str(outdir / "fuse"), "--ground-truth", str(rec.links["ground_truth"]), "-o",
                str(outdir / "eval_fusion.json")]
    if stage == "eval-nbv":
        return [str(rec.links["ground_truth"]), "-o", str(outdir / EVAL_NBV_FILE)]
    if stage == "eval-segment":
        return [str(outdir / "segment"), "--ground-truth", str(labels_file(rec)), "-o", str(outdir / EVAL_SEGMENT_FILE)]
    raise KeyError(stage)


def _option_args(stage: str, outdir: Path, options: dict) -> list[str]:
    """Plan options ({"voxel-size": 0.02, "bilateral": true, "size": [2, 2, 1]}) as the command's arguments."""
    cmd = _command(stage)
    _, reserved, files = _COMMANDS[stage]
    by_flag = {o[2:]: p for p in cmd.params if isinstance(p, click.Option) for o in p.opts if o.startswith("--")}
    args: list[str] = []
    for key, value in options.items():
        if key in _SWEEP_OPTIONS and stage == "eval-segment":
            raise ConfigError(f"option {key!r} belongs to eval segment --sweep (generated scenes), not to a recording")
        if key in reserved or key == "help":
            raise ConfigError(f"option {key!r} is set by batch itself")
        param = by_flag.get(key)
        if param is None:
            raise ConfigError(f"unknown option {key!r} of kinfu {stage}")
        flag = f"--{key}"
        if key in files:  # one file per recording, in its folder: a path here would be shared by all
            if not isinstance(value, bool):
                raise ConfigError(f"option {key!r}: expected true (writes {files[key]}) or false, got {value!r}")
            args += [flag, str(outdir / files[key])] if value else []
        elif param.is_flag:
            if not isinstance(value, bool):
                raise ConfigError(f"option {key!r}: expected true or false, got {value!r}")
            args += [flag] if value else []
        elif isinstance(value, (list, tuple)):
            if param.multiple:
                for v in value:
                    args += [flag, ",".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v)]
            else:
                args += [flag, ",".join(map(str, value))]
        elif isinstance(value, (dict, type(None))):
            raise ConfigError(f"option {key!r}: expected a value, got {value!r}")
        else:
            args += [flag, str(value).lower() if isinstance(value, bool) else str(value)]
    return args


def _args(stage: str, rec, options: dict, force: bool) -> list[str]:
    return (_base_args(stage, rec) + _option_args(stage, rec.output, options) + ["--quiet"]
            + (["--force"] if force else []))


def _prog(stage: str) -> str:
    return f"kinfu {stage.replace('-', ' ')}"


def check_stage(stage: str, rec, options: dict) -> None:
    """Parse the stage's arguments with its command (types, choices) and build the parameter objects the command
    would build from them, with the library's own range checks (the command module's `check_options`), without
    reading any input: a bad value is a ConfigError naming the option as the plan spells it. Options the command
    refuses in the mode the plan gives it (its INAPPLICABLE rules) are refused here too; those it only warns
    about are warnings of the stage when it runs."""
    cmd = _command(stage)
    try:
        ctx = cmd.make_context(_prog(stage), _args(stage, rec, options, False))
    except click.ClickException as exc:
        raise ConfigError(" ".join(exc.format_message().split())) from None
    try:
        check_inapplicable(ctx, getattr(_module(stage), "INAPPLICABLE", ()), warn=False)
        _module(stage).check_options(ctx.params)
    except KinfuError as exc:
        raise ConfigError(_plan_spelling(_flag_message(cmd, exc), cmd)) from None


def _plan_spelling(message: str, cmd: click.Command) -> str:
    """The command's flags in a message as the plan names its options: "--voxel-size: expected ..." ->
    "voxel-size: expected ...", "--grasp needs ...: drop --no-superquadrics" -> "grasp needs ...: drop
    no-superquadrics" (other text with dashes is left alone)."""
    longs = {o[2:] for p in cmd.params if isinstance(p, click.Option) for o in (*p.opts, *p.secondary_opts)
             if o.startswith("--")}
    return re.sub(r"(?<![\w-])--([a-z][a-z0-9-]*)", lambda m: m[1] if m[1] in longs else m[0], message)


def _flag_message(cmd: click.Command, exc: KinfuError) -> str:
    """A library error as the command line shows it: the parameter named by its flag."""
    if not exc.parameter:
        return str(exc)
    flags = option_flags(cmd, exc.parameter)
    return f"{flags}: {exc.detail}"


def run_stage(stage: str, rec, options: dict, force: bool) -> StageRun:
    """Run the stage's command in this process (its warnings captured, nothing printed); KinfuError with the
    command's one-line message when it fails."""
    cmd = _command(stage)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            cmd.main(_args(stage, rec, options, force), prog_name=_prog(stage), standalone_mode=False)
    except KinfuError as exc:
        raise KinfuError(_flag_message(cmd, exc)) from None
    except click.ClickException as exc:
        raise KinfuError(exc.format_message()) from None
    except OSError as exc:
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        raise KinfuError(where + str(exc.strerror or exc)) from None
    prefix = "kinfu: warning: "
    warnings = [line[len(prefix):] for line in err.getvalue().splitlines() if line.startswith(prefix)]
    return StageRun(numbers=_NUMBERS[stage](rec.output), warnings=warnings)


def _read(path: Path) -> dict:
    return json.loads(path.read_text())


def _fuse_numbers(outdir: Path) -> dict:
    r = _read(outdir / "fuse" / "report.json")
    return {"frames_used": r["frames"]["used"], **{k: r["counts"][k] for k in ("occupied", "empty", "unknown")},
            "voxel_size": r["grid"].get("voxel_size")}


def _poi_numbers(outdir: Path) -> dict:
    d = _read(outdir / "pois.json")
    return {"pois": len(d["pois"]), "tasks": len(d.get("tasks") or [])}


def _nbv_numbers(outdir: Path) -> dict:
    d = _read(outdir / "views.json")
    valid = [p for p in d["pois"] if p["valid"]]
    return {"pois": len(d["pois"]), "pois_with_views": len(valid),
            "reconstructed": sum(bool(p["reconstructed"]) for p in d["pois"]),
            "best_gain": max((p["best_gain"] for p in valid), default=None)}


def _segment_numbers(outdir: Path) -> dict:
    d = _read(outdir / "segment" / "segments.json")
    return {"segments": sum(s["kind"] == "object" for s in d["segments"]),
            "support_plane": d["support_plane"] is not None, "points": d["points"]}


_NUMBERS = {"fuse": _fuse_numbers, "poi": _poi_numbers, "nbv": _nbv_numbers, "segment": _segment_numbers}


def _file_options(stage: str) -> tuple[str, ...]:
    """The command's options that read a file (click.Path) and that a plan may set (nbv's candidates and
    camera-info): batch resolves them against the plan's folder and fingerprints the files."""
    if stage not in _COMMANDS:
        return ()
    _, reserved, files = _COMMANDS[stage]
    names = (max(p.opts, key=len)[2:] for p in _command(stage).params
             if isinstance(p, click.Option) and isinstance(p.type, click.Path))
    return tuple(n for n in names if n not in reserved and n not in files)


def _extras(stage: str) -> tuple[tuple[str, str], ...]:
    """(option, file) of the files the stage writes into the recording's folder only when that option is true
    (plots, viewer files)."""
    return tuple(_COMMANDS[stage][2].items()) if stage in _COMMANDS else ()


def batch_stages() -> dict[str, StageSpec]:
    """The stage table in pipeline order (a stage comes after the stages it needs)."""
    def spec(name, needs, inputs, outputs, claims, **kw):
        return StageSpec(name=name, needs=needs, inputs=inputs, outputs=outputs, claims=claims,
                         check=kw.pop("check", partial(check_stage, name)), run=kw.pop("run", partial(run_stage, name)),
                         file_options=_file_options(name), extras=_extras(name), **kw)

    volume = "fuse/volume.npz"
    return {
        "fuse": spec("fuse", (), (RECORDING,), (volume, "fuse/report.json"), ("fuse",)),
        "poi": spec("poi", (), (RECORDING,), ("pois.json",), ("pois.json",)),
        "nbv": spec("nbv", ("fuse", "poi"), (volume, "pois.json"), ("views.json",), ("views.json",)),
        "segment": spec("segment", ("fuse",), (volume,), ("segment/segments.json",), ("segment",)),
        "diff": spec("diff", ("fuse",), _diff_inputs, ("diff/changes.json",), ("diff",), wants=("poi",),
                     links=("before",), reads_others=("fuse",)),
        "eval-fusion": spec("eval-fusion", ("fuse",), (volume, "fuse/mesh.ply", "<ground_truth>"),
                            ("eval_fusion.json",), ("eval_fusion.json",), links=("ground_truth",)),
        "eval-nbv": spec("eval-nbv", (), ("<ground_truth>",), (EVAL_NBV_FILE,), (EVAL_NBV_FILE,),
                         links=("ground_truth",), check=check_eval_nbv),
        "eval-segment": spec("eval-segment", ("segment",), ("segment/segments.json", "<ground_truth>"),
                             (EVAL_SEGMENT_FILE,), (EVAL_SEGMENT_FILE,), links=("ground_truth",),
                             check=check_eval_segment),
        "eval-poi": spec("eval-poi", ("poi",), ("pois.json", "<ground_truth>"), (EVAL_POI_FILE,), (EVAL_POI_FILE,),
                         links=("ground_truth",), check=check_eval_poi, run=run_eval_poi),
        "viz": spec("viz", (), _viz_parts, _viz_output, _viz_output, wants=tuple(VIEWER_FILES), links=("viz",),
                    check=check_viz, run=run_viz),
    }


def _diff_inputs(rec) -> tuple[str, ...]:
    return ("<before>", "fuse/volume.npz", *(("pois.json",) if "poi" in rec.stages else ()))


def _viz_output(rec) -> tuple[str, ...]:
    return (rec.links["viz"].name,)


def _diff_numbers(outdir: Path) -> dict:
    d = _read(outdir / "diff" / "changes.json")
    out = {"removed": d["counts"]["regions"]["removed"], "added": d["counts"]["regions"]["added"]}
    if d.get("pois") is not None:
        out.update(poi_precision=d["pois"]["precision"], poi_recall=d["pois"]["recall"])
    return out


def _eval_fusion_numbers(outdir: Path) -> dict:
    r = _read(outdir / "eval_fusion.json")["reconstruction"]
    return {"precision": r["precision"], "completeness": r["completeness"], "fscore": r["fscore"],
            "accuracy_mean_m": r["accuracy"].get("mean")}


_NUMBERS.update({"diff": _diff_numbers, "eval-fusion": _eval_fusion_numbers})

EVAL_NBV_FILE = "eval_nbv.json"
EVAL_SEGMENT_FILE = "eval_segment.json"
#: the labels eval-segment scores against, in the recording's ground truth (kinfu synth writes both; the room
#: scene only labels.ply); the first found is used
LABEL_FILES = ("labels.npz", "labels.ply")


def labels_file(rec) -> Path:
    gt = rec.links["ground_truth"]
    return next((gt / n for n in LABEL_FILES if (gt / n).is_file()), gt / LABEL_FILES[0])


def check_eval_segment(rec, options: dict) -> None:
    """The labels must be there before any work (the plan only checked the ground-truth folder)."""
    check_stage("eval-segment", rec, options)
    path = labels_file(rec)
    if not path.is_file():
        raise ConfigError(f"no {path} (kinfu synth writes it for tabletop scenes): give the entry a 'ground-truth' "
                          "folder holding labels.npz, or its own 'stages' without eval-segment")


def check_eval_nbv(rec, options: dict) -> None:
    """The simulated loop rebuilds the scene from the ground truth: its files must be there before any work."""
    check_stage("eval-nbv", rec, options)
    gt = rec.links["ground_truth"]
    if missing := [n for n in ("changes.json", "camera_poses.txt") if not (gt / n).is_file()]:
        raise ConfigError(f"no {gt / missing[0]} (eval-nbv simulates the scene of a kinfu synth ground_truth/ "
                          "folder)")


def _eval_nbv_numbers(outdir: Path) -> dict:
    """Per strategy: unknown voxels left in the POI spheres (POI loop) or near the objects (exploration)."""
    d = _read(outdir / EVAL_NBV_FILE)
    out = {}
    for name, r in d["strategies"].items():
        out[f"{name}_unknown_left"] = r["final_unknown"] if "final_unknown" in r else r["unknown_near"][-1]
    return out


def _eval_segment_numbers(outdir: Path) -> dict:
    d = _read(outdir / EVAL_SEGMENT_FILE)
    return {k: d[k] for k in ("boundary_precision", "boundary_recall", "bce", "object_recall", "objects_found",
                              "objects_total")}


_NUMBERS.update({"eval-nbv": _eval_nbv_numbers, "eval-segment": _eval_segment_numbers})

EVAL_POI_FILE = "eval_poi.json"


def _eval_poi_radius(options: dict) -> float:
    from kinfu_cli.evaluation.poi import MATCH_RADIUS

    if unknown := set(options) - {"match-radius"}:
        raise ConfigError(f"unknown option {sorted(unknown)[0]!r} of eval-poi (known: match-radius)")
    radius = options.get("match-radius", MATCH_RADIUS)
    if isinstance(radius, bool) or not isinstance(radius, (int, float)) or not radius > 0:
        raise ConfigError(f"option 'match-radius': expected a positive distance in metres, got {radius!r}")
    return float(radius)


def check_eval_poi(rec, options: dict) -> None:
    _eval_poi_radius(options)


def run_eval_poi(rec, options: dict, force: bool) -> StageRun:
    """The recording's POIs (pois.json) scored against its true changes (ground_truth/changes.json) with the
    paper's rule: a POI within the radius of a change is a true positive (RAS 2016 Sec. 6.2)."""
    import numpy as np

    from kinfu_cli.core.atomic import write_json
    from kinfu_cli.core.pois import read_pois
    from kinfu_cli.evaluation.poi import score_pois
    from kinfu_cli.sim.scenario import load_ground_truth

    radius = _eval_poi_radius(options)
    pois = read_pois(rec.output / "pois.json")
    changes = np.asarray(load_ground_truth(rec.links["ground_truth"]).change_positions, dtype=float).reshape(-1, 3)
    tp, fp, fn = score_pois(np.array([p.position for p in pois]).reshape(-1, 3), changes, radius)
    # a ratio with nothing to divide by is undefined (null), not 0.0, which would read as all wrong
    doc = {"pois": len(pois), "changes": len(changes), "radius": radius, "tp": tp, "fp": fp, "fn": fn,
           "precision": tp / (tp + fp) if tp + fp else None,
           "recall": (len(changes) - fn) / len(changes) if len(changes) else None,
           "ground_truth": str(rec.links["ground_truth"]), "pois_file": str(rec.output / "pois.json")}
    warnings = [f"{rec.output / 'pois.json'}: {what} is undefined (null): {why}" for what, why in
                (("precision", "no POI was found"), ("recall", "the ground truth holds no change"))
                if doc[what] is None]
    out = rec.output / EVAL_POI_FILE
    write_json(out, doc | {"warnings": warnings})  # atomic, recorded as kinfu's
    return StageRun(numbers={k: doc[k] for k in ("precision", "recall", "tp", "fp", "fn")}, warnings=warnings)


def _viz_parts(rec) -> tuple[str, ...]:
    return tuple(VIEWER_FILES[s] for s in rec.stages if s in VIEWER_FILES)


def check_viz(rec, options: dict) -> None:
    if options:
        raise ConfigError(f"the viewer stage takes no options, got {', '.join(sorted(options))}")


def run_viz(rec, options: dict, force: bool) -> StageRun:
    """The recording's one viewer file, combined from the viewer files its stages wrote."""
    from kinfu_cli.report.viewer_merge import merge_viewers

    out = rec.links["viz"]
    summary = merge_viewers(out, [rec.output / p for p in _viz_parts(rec)])  # atomic, recorded as kinfu's
    warnings = []
    if len(summary["frames"]) > 1:
        warnings.append(f"{out.name}: the stages' results are in different frames ({', '.join(summary['frames'])})"
                        " and will not line up")
    return StageRun(numbers={"messages": sum(summary["topics"].values()), "topics": len(summary["topics"]),
                             "restamped": summary["restamped"]}, warnings=warnings)
