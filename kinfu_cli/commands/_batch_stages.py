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
from functools import partial
from pathlib import Path

import click

from kinfu_cli.batch.stages import RECORDING, StageRun, StageSpec
from kinfu_cli.commands._options import PARAMETER_FLAGS
from kinfu_cli.core.errors import ConfigError, KinfuError

# stage -> (module of the command, options batch sets itself, options taking an output file whose `true` in the
# plan means "this file in the recording's output folder"). A viewer output option (a file) goes in the last.
_COMMANDS = {
    "fuse": ("fuse", {"output", "json", "quiet", "force", "init", "clear-pois"}, {"viz": "fuse.mcap"}),
    "poi": ("poi", {"output", "json", "quiet", "force"}, {"plot": "pois.png", "viz": "pois.mcap"}),
    "nbv": ("nbv", {"output", "json", "quiet", "force", "pois", "mode"}, {"plot": "views.png", "viz": "views.mcap"}),
    "segment": ("segment", {"output", "json", "quiet", "force"}, {"viz": "segment.mcap"}),
}


def _command(stage: str) -> click.Command:
    import importlib

    return importlib.import_module(f"kinfu_cli.commands.{_COMMANDS[stage][0]}").command


def _base_args(stage: str, recording: Path, outdir: Path) -> list[str]:
    """The positional input and the outputs of the stage's command for one recording."""
    volume = str(outdir / "fuse" / "volume.npz")
    return {"fuse": [str(recording), "-o", str(outdir / "fuse")],
            "poi": [str(recording), "-o", str(outdir / "pois.json")],
            "nbv": [volume, "--pois", str(outdir / "pois.json"), "-o", str(outdir / "views.json")],
            "segment": [volume, "-o", str(outdir / "segment")]}[stage]


def _option_args(stage: str, outdir: Path, options: dict) -> list[str]:
    """Plan options ({"voxel-size": 0.02, "bilateral": true, "size": [2, 2, 1]}) as the command's arguments."""
    cmd = _command(stage)
    _, reserved, files = _COMMANDS[stage]
    by_flag = {o[2:]: p for p in cmd.params if isinstance(p, click.Option) for o in p.opts if o.startswith("--")}
    args: list[str] = []
    for key, value in options.items():
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


def _args(stage: str, recording: Path, outdir: Path, options: dict, force: bool) -> list[str]:
    return (_base_args(stage, recording, outdir) + _option_args(stage, outdir, options) + ["--quiet"]
            + (["--force"] if force else []))


def check_stage(stage: str, recording: Path, outdir: Path, options: dict) -> None:
    """Parse the stage's arguments with its command (types, choices, ranges) without running it."""
    cmd = _command(stage)
    try:
        cmd.make_context(f"kinfu {stage}", _args(stage, recording, outdir, options, False))
    except click.ClickException as exc:
        raise ConfigError(" ".join(exc.format_message().split())) from None


def _flag_message(cmd: click.Command, exc: KinfuError) -> str:
    """A library error as the command line shows it: the parameter named by its flag."""
    if not exc.parameter:
        return str(exc)
    options = {p.name: max(p.opts, key=len) for p in cmd.params if isinstance(p, click.Option)}
    flags = "/".join(PARAMETER_FLAGS.get(n) or options.get(n) or n for n in exc.parameter.split("/"))
    return f"{flags}: {exc.detail}"


def run_stage(stage: str, recording: Path, outdir: Path, options: dict, force: bool) -> StageRun:
    """Run the stage's command in this process (its warnings captured, nothing printed); KinfuError with the
    command's one-line message when it fails."""
    cmd = _command(stage)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            cmd.main(_args(stage, recording, outdir, options, force), prog_name=f"kinfu {stage}",
                     standalone_mode=False)
    except KinfuError as exc:
        raise KinfuError(_flag_message(cmd, exc)) from None
    except click.ClickException as exc:
        raise KinfuError(exc.format_message()) from None
    except OSError as exc:
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        raise KinfuError(where + str(exc.strerror or exc)) from None
    prefix = "kinfu: warning: "
    warnings = [line[len(prefix):] for line in err.getvalue().splitlines() if line.startswith(prefix)]
    return StageRun(numbers=_NUMBERS[stage](outdir), warnings=warnings)


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


def batch_stages() -> dict[str, StageSpec]:
    """The stage table in pipeline order (a stage comes after the stages it needs)."""
    def spec(name, needs, inputs, outputs, claims):
        return StageSpec(name=name, needs=needs, inputs=inputs, outputs=outputs, claims=claims,
                         check=partial(check_stage, name), run=partial(run_stage, name))

    return {
        "fuse": spec("fuse", (), (RECORDING,), ("fuse/volume.npz", "fuse/report.json"), ("fuse",)),
        "poi": spec("poi", (), (RECORDING,), ("pois.json",), ("pois.json",)),
        "nbv": spec("nbv", ("fuse", "poi"), ("fuse/volume.npz", "pois.json"), ("views.json",), ("views.json",)),
        "segment": spec("segment", ("fuse",), ("fuse/volume.npz",), ("segment/segments.json",), ("segment",)),
    }
