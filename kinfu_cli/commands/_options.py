"""Library parameter names whose command-line flag is not simply the option of the same Python name.

Library errors name parameters (`ConfigError(..., parameter="vfov_extra_deg")`); the CLI shows the
flag instead: this table first, else the option whose Python name is the parameter. Also the options every
writing command shares: `--force`, and the check of its outputs before any work.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import click
from click.core import ParameterSource

from kinfu_cli.core.errors import ConfigError, KinfuError, VolumeError
from kinfu_cli.core.ownership import claim_output, recording_folders, refuse_inside_folders
from kinfu_cli.commands._output import OPTION_WARNINGS
from kinfu_cli.commands._output_path import OutputPath, output_kind_of, output_kind_problem

PARAMETER_FLAGS: dict[str, str] = {
    "vfov_extra_deg": "--vfov-extra",
    "concavity_tolerance_deg": "--concavity-tolerance",
    "sanity_angle_deg": "--sanity-angle",
    "oscillation_deg": "--oscillation",
    "region_radius": "--poi-radius",
    "modes": "--mode",
    "up_tolerance_deg": "--up-tolerance",
    "cut_concave_fraction": "--concave-cut",
    "frame_rate_hz": "--frame-rate",
    "hand_rate_hz": "--hand-rate",
}


def option_flags(cmd: click.Command | None, parameter: str) -> str:
    """The command-line flag(s) of a library parameter name ("a/b" for two) in `cmd`: PARAMETER_FLAGS first, else
    its option of that Python name, else the name as the library gave it."""
    options = {p.name: max(p.opts, key=len) for p in (cmd.params if cmd else []) if isinstance(p, click.Option)}
    return "/".join(PARAMETER_FLAGS.get(n) or options.get(n) or n for n in parameter.split("/"))

def _not_empty(ctx: click.Context, param: click.Parameter, value):
    """click callback: an option given as '' (a shell variable left unset) is refused, not read as its default
    (--origin '' fused at the automatic origin, --camera-frame '' read the images' own frame)."""
    if isinstance(value, str) and not value.strip():
        raise click.BadParameter("expected a value, got an empty one", ctx=ctx, param=param)
    return value


def refuse_empty_values(cmd: click.Command) -> click.Command:
    """Give every text option of `cmd` that defaults to None (a topic, a frame, a list of numbers) the check that
    an empty value is an error: the commands' own parsers read '' as "not given". Options with a default of their
    own ('' meaning none, as eval poi's --noise) and those with a callback of their own are left as they are."""
    for p in cmd.params:
        if (isinstance(p, click.Option) and not p.is_flag and p.default is None and p.callback is None
                and isinstance(p.type, click.types.StringParamType)):
            p.callback = _not_empty
    return cmd


def comma_items(text: str, option: str) -> list[str]:
    """The items of a comma-separated option value, stripped ([] for a blank value); an empty item ('1,,2', a
    trailing comma) is an error naming the option (it was skipped, and the rest taken as what was meant)."""
    if not text.strip():
        return []
    items = [t.strip() for t in text.split(",")]
    if any(not t for t in items):
        raise KinfuError(f"{option} {text!r}: an empty item; expected comma-separated values without gaps")
    return items


def comma_numbers(text: str, option: str) -> list[float] | None:
    """The numbers of a fixed-count option ('x,y,z', 'lo,hi', ...), each a finite float, or None when an item is
    not one (the caller says what was expected, with the count); an empty item ('1,,2', a trailing comma) is
    comma_items's error, in the words of the list options."""
    try:
        values = [float(t) for t in comma_items(text, option)]
    except ValueError:
        return None
    return values if all(math.isfinite(v) for v in values) else None


def comma_values(text: str, option: str) -> list[str]:
    """comma_items of an option whose blank value means nothing (no "none" to choose): '' is an error naming the
    option, as refuse_empty_values says it, where it was read as an empty list (eval poi --speed '' ran speed 1)."""
    if not text.strip():
        raise KinfuError(f"{option}: expected a value, got an empty one")
    return comma_items(text, option)


#: `kinfu eval segment` options that mean something only with --sweep (long flags without the dashes): the
#: command refuses them without --sweep, batch's eval-segment stage (one recording, never a sweep) refuses them
SWEEP_ONLY_OPTIONS = frozenset({"sweep-parameter", "sweep-values", "color-distance", "method", "color", "photometric",
                                "scene", "scenes", "resolution"})


def given_options(ctx: click.Context, flags: Iterable[str]) -> list[str]:
    """The options among `flags` (long flags without the dashes) that the user set, by click's parameter source
    (an option given at its default value counts, one left out does not), shown as their flags."""
    wanted = set(flags)
    given = []
    for p in ctx.command.params:
        long = [o for o in p.opts if o.startswith("--")]
        if (isinstance(p, click.Option) and wanted.intersection(o[2:] for o in long)
                and ctx.get_parameter_source(p.name) not in (None, ParameterSource.DEFAULT)):
            given.append("/".join(long + list(p.secondary_opts)))
    return given


@dataclass(frozen=True)
class Inapplicable:
    """Options (long flags without the dashes) that have no effect at all in some mode of their command.

    mode: from the command's parsed options (click's parameter dict), the mode in which they have none, as the
    message says it ("with --pose forced", "without --multi-sq"), else None (they apply). target: where they
    apply ("to --pose icp or hint"), for the error. warn: a warning (the default) or an error (see
    check_inapplicable). message: the error's own wording instead ("{flags}" is replaced by the options given).
    """

    options: tuple[str, ...]
    mode: Callable[[dict], str | None]
    target: str = ""
    warn: bool = True
    message: str | None = None


def check_inapplicable(ctx: click.Context, rules: Iterable[Inapplicable], *, warn: bool = True) -> None:
    """Refuse, or warn about, options given on the command line in a mode of the command where they have no
    effect (they were ignored without a word). An option counts as given by click's parameter source: one given
    at its default value is given, one left out is not. Called first by each command with its INAPPLICABLE
    rules, and by kinfu batch's check of a plan (warn=False: only the refusals, before any work; the warnings
    come when the stage runs, into manifest.json). The warnings also go first into the command's result
    document (report.json, pois.json, ...: _output.with_option_warnings).

    The rule: warn (`kinfu: warning: --x has no effect with --y z (ignored)`, exit 0): the run computes what its
    mode computes, as it did before these checks, and the line tells the user which of their options it did not
    use; a script or batch plan that sets an option for runs of every mode (a seed, a hand rate, fuse's tracking
    options for recordings with and without TF) keeps working. Refuse (ConfigError, one `kinfu: error:` line,
    exit 2, before any work) only where kinfu refused already: nbv --mode objects with the POI mode's options,
    segment's --grasp-* without --grasp, eval segment's sweep options without --sweep.
    """
    refused, warnings = [], []
    for rule in rules:
        mode = rule.mode(ctx.params)
        given = given_options(ctx, rule.options) if mode is not None else []
        if not given:
            continue
        flags, one = ", ".join(given), len(given) == 1
        if rule.warn:
            warnings.append(f"{flags} {'has' if one else 'have'} no effect {mode} (ignored)")
        elif rule.message is not None:
            refused.append(rule.message.replace("{flags}", flags))
        else:
            refused.append(f"{flags}: {'has' if one else 'have'} no effect {mode}; "
                           f"{'it applies' if one else 'they apply'} {rule.target}")
    if refused:  # the first: one line, and no warning printed before it
        raise ConfigError(refused[0])
    for w in warnings if warn else ():
        click.echo(f"kinfu: warning: {w}", err=True)
    if warn:  # and into the command's result document (_output.with_option_warnings)
        ctx.meta[OPTION_WARNINGS] = warnings


def volume_file(path: Path) -> Path:
    """A volume argument: the file itself, or a `kinfu fuse` output folder's volume.npz (its ternary.npz when it
    holds only that), as grasp takes a segment folder for its segments.json."""
    path = Path(path)
    if not path.is_dir():
        return path
    for name in ("volume.npz", "ternary.npz"):
        if (path / name).is_file():
            return path / name
    raise VolumeError(f"{path}: a folder without volume.npz or ternary.npz; expected a volume file or a kinfu fuse "
                      f"output folder")


def bag_folder(recording: str | os.PathLike | None) -> Path | None:
    """The ROS 2 bag folder a recording named by one of its files belongs to (a metadata.yaml beside it): the
    reader reads the whole bag, so the folder is an input too (its files never written over); else None."""
    if recording is None:
        return None
    path = Path(recording)
    return path.parent if path.is_file() and (path.parent / "metadata.yaml").is_file() else None


def force_option(func):
    """`--force`: write over an existing output that kinfu did not write (never over an input)."""
    return click.option("--force", is_flag=True,
                        help="Write over an existing output that kinfu did not write (an input is never written "
                             "over; kinfu replaces only its own files).")(func)


def claim_outputs(outputs: dict[str, str | os.PathLike | None], inputs: Iterable[str | os.PathLike | None],
                  force: bool, *, recordings: Iterable[str | os.PathLike | None] = ()) -> None:
    """Refuse, before any work, outputs that are inputs, hold an input, are empty, or exist without being
    kinfu's (unless force); keys are the commands' option names, so the error shows the flag. recordings: the
    recording inputs, whose folder (a ROS 2 bag, core.ownership.recording_folders) no output may lie inside."""
    inputs = list(inputs)
    whole = [f for r in recordings for f in recording_folders(r)]
    seen: dict[str, str] = {}
    for name, path in outputs.items():
        if path is not None:
            claim_output(path, inputs, force=force, parameter=name)
            refuse_inside_folders(path, whole, parameter=name)
            real = os.path.realpath(path)
            if real in seen:  # the second write would replace the first (poi -o p.json --plot p.json)
                raise KinfuError(f"{path} is given for both; name two different paths",
                                 parameter=f"{seen[real]}/{name}")
            for other, other_name in seen.items():  # segment -o seg --viz seg/segments.json wrote over its result
                if os.path.commonpath([real, other]) in (real, other):
                    inner, outer = (path, outputs[other_name]) if len(real) > len(other) else (outputs[other_name], path)
                    raise KinfuError(f"{inner} lies inside the output folder {outer}; name a path outside it",
                                     parameter=f"{other_name}/{name}")
            seen[real] = name
    for name, path in outputs.items():  # after the checks above, whose errors say more (an input, one path twice)
        kind = None if path is None else output_kind_of(name)
        problem = None if kind is None else output_kind_problem(path, kind)
        if problem is not None:
            raise KinfuError(problem, parameter=name)


def result_options(*, output: str | None = "Write the results as JSON here.", plot: str | None = None,
                   json: str = "Print the results JSON to stdout instead of the table.",
                   quiet: str = "No progress output.", force: bool = True, dir_okay: bool = False):
    """The option block the evaluation commands end with, shown in this order: --plot FILE, -o/--output FILE,
    --json, --quiet, --force; each help text is the command's own (None leaves --plot / --output out, force=False
    --force). The command receives plot, output, as_json, quiet and force. dir_okay: whether click lets a
    folder through as --plot / --output (ownership is checked by claim_outputs either way)."""
    def decorate(func):
        if force:
            func = force_option(func)
        func = click.option("--quiet", is_flag=True, help=quiet)(func)
        func = click.option("--json", "as_json", is_flag=True, help=json)(func)
        for name, flags, text, kind in (("output", ("-o", "--output"), output, "json"),
                                        ("plot", ("--plot",), plot, "image")):
            if text is not None:
                func = click.option(*flags, name, type=OutputPath(dir_okay=dir_okay, kind=kind), default=None,
                                    help=text)(func)
        return func

    return decorate
