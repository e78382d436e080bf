"""The `kinfu` click group. Thin: sub-commands live in kinfu_cli/commands/ and call library code.

Commands load lazily (click's documented lazy-loading pattern): `kinfu fuse` imports the fuse command's
module and what it needs, not the whole package, so each command starts as fast as its own stage allows.
COMMANDS names every command's module; a module defines `command` (a click.Command).
"""

from __future__ import annotations

import importlib
import sys

import click

from kinfu_cli import __version__
from kinfu_cli.commands._options import option_flags, refuse_empty_values
from kinfu_cli.core.errors import KinfuError
from kinfu_cli.core.ownership import ForeignOutputError

# command name -> module in kinfu_cli.commands; a dict is a group of sub-commands
COMMANDS: dict[str, str | dict[str, str]] = {
    "info": "info",
    "import": "import_",
    "export": "export",
    "synth": "synth",
    "fuse": "fuse",
    "poi": "poi",
    "segment": "segment",
    "nbv": "nbv",
    "batch": "batch",
    "diff": "diff",
    "grasp": "grasp",
    "localize": "localize",
    "eval": {"poi": "eval_poi", "fusion": "eval_fusion", "nbv": "eval_nbv", "segment": "eval_segment",
             "grasp": "eval_grasp", "localize": "eval_localize"},
}

# each command's one-line help, so `kinfu --help` lists them without importing every stage (a test keeps
# these equal to the commands' own first docstring lines)
SUMMARIES: dict[str, str] = {
    "info": "Show topics, rates, time span, detected roles and TF tree of a recording.",
    "import": "Convert an RGB-D frame folder (7-Scenes/3DMatch, TUM) into MCAP/bag/ROS 2.",
    "export": "Write a recording's RGB-D frames as a frame folder, or a TUM trajectory.",
    "synth": "Write a synthetic tabletop or room recording (MCAP, bag, ROS 2) with ground truth.",
    "fuse": "Fuse depth frames into a ternary TSDF volume, mesh and cloud.",
    "poi": "Points of interest from the hand trajectory (GMM-AS or ZVC).",
    "segment": "Segments, saliency and superquadrics of a fused volume.",
    "nbv": "Rank next-best views around each POI by information gain.",
    "batch": "Run the stages of a plan over many recordings on Dask (resumable).",
    "diff": "Removed / added regions between two volumes of one place; POIs scored on them.",
    "grasp": "Grasp poses for segmented objects from their superquadrics.",
    "localize": "Pose of a known mesh from surface points (MUPF); --models: recognition.",
    "eval": "Score results against ground truth, tables like the papers'.",
    "eval poi": "Score GMM-AS / ZVC POIs on a hand data set (paper Tables 2-4).",
    "eval fusion": "Reconstruction error and object measures (paper Table 1) vs ground truth.",
    "eval nbv": "Closed NBV loop in simulation: POI views vs random/fixed, objects vs standard.",
    "eval segment": "Segmentation boundary P/R, BCE, object recall vs labels; --sweep: PR curves.",
    "eval grasp": "Grasp constraint satisfaction, overlap, penetration and time.",
    "eval localize": "MUPF vs Scaling Series vs RANSAC+ICP (thesis Table 4.2); recognition (ch. 5).",
}


class _LazyGroup(click.Group):
    """A group whose sub-commands are imported from their modules when first used."""

    def __init__(self, *args, modules: dict[str, str | dict[str, str]], **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.modules = modules
        self.last_resolved: click.Command | None = None  # the sub-command being run, for error messages

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(self.modules)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list from SUMMARIES: help stays fast, no stage is imported for it."""
        prefix = "" if ctx.parent is None else f"{ctx.info_name} "
        names = self.list_commands(ctx)
        limit = formatter.width - 6 - max(map(len, names), default=0)  # as click's own listing
        rows = [(name, click.Command(name, help=SUMMARIES[prefix + name]).get_short_help_str(limit) if prefix + name in SUMMARIES
                 else self.get_command(ctx, name).get_short_help_str(limit)) for name in names]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name in self.commands:
            self.last_resolved = self.commands[name]
            return self.last_resolved
        target = self.modules.get(name)
        if target is None:
            return None
        if isinstance(target, dict):
            cmd: click.Command = _LazyGroup(name=name, modules=target,
                                            help=f"Score against ground truth: {', '.join(sorted(target))}.",
                                            short_help="Score results against ground truth, tables like the papers'.")
        else:
            cmd = refuse_empty_values(importlib.import_module(f"kinfu_cli.commands.{target}").command)
        self.commands[name] = self.last_resolved = cmd
        return cmd


def _flags_of(parameter: str, group: _LazyGroup) -> str:
    """The command-line flag(s) of a library parameter name in the command being run (option_flags)."""
    cmd: click.Command | None = group
    while isinstance(cmd, _LazyGroup):
        cmd = cmd.last_resolved
    return option_flags(cmd, parameter)


def _one_line(message: str) -> str:
    """Messages may quote names from a recording (a frame_id with a newline): keep the error one line."""
    return message.strip().replace("\r", "\\r").replace("\n", "\\n")


def _usage_message(exc: click.ClickException) -> str:
    """click's usage errors as `--flag: what is wrong` (no usage block)."""
    param = getattr(exc, "param", None)
    if isinstance(exc, click.BadParameter) and not isinstance(exc, click.MissingParameter) and param is not None:
        name = max(param.opts, key=len) if isinstance(param, click.Option) else param.human_readable_name
        return f"{name}: {exc.message}"
    return exc.format_message()


def _caused_by_interrupt(exc: BaseException) -> bool:
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


class _Main(_LazyGroup):
    """The root group: every failure ends as one `kinfu: error: ...` line on stderr (exit 2), Ctrl-C as
    `kinfu: interrupted` (exit 130); no traceback, no usage block."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except KinfuError as exc:
            message = f"{_flags_of(exc.parameter, self)}: {exc.detail}" if exc.parameter else str(exc)
            if isinstance(exc, ForeignOutputError):
                message += " or pass --force"
            click.echo(f"kinfu: error: {_one_line(message)}", err=True)
            ctx.exit(exc.exit_code)
        except (KeyboardInterrupt, click.Abort):
            click.echo("kinfu: interrupted", err=True)
            ctx.exit(130)
        except MemoryError:
            click.echo(f"kinfu: error: out of memory{self._memory_advice(ctx)}", err=True)
            ctx.exit(2)
        except EOFError as exc:  # kinfu reads no terminal input: a reader met the end of a cut file (click's main
            # would take it for Ctrl-D and abort)
            why = f" ({exc})" if str(exc) else ""
            click.echo(f"kinfu: error: {_one_line(f'an input file ends early, it may be truncated{why}')}", err=True)
            ctx.exit(2)
        except OSError as exc:
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            click.echo(f"kinfu: error: {_one_line(where + str(exc.strerror or exc))}", err=True)
            ctx.exit(2)
        except Exception as exc:  # a Ctrl-C inside numba's dispatcher or an import arrives wrapped
            if not _caused_by_interrupt(exc):
                raise
            click.echo("kinfu: interrupted", err=True)
            ctx.exit(130)

    def _memory_advice(self, ctx: click.Context) -> str:
        """The grid options of the command that ran out of memory, when it has them (nbv, poi, ... do not)."""
        name = ctx.invoked_subcommand
        command = self.get_command(ctx, name) if name else None
        if isinstance(command, click.Group):  # eval fusion, eval nbv, ...: the leaf command is not known here
            return ""
        flags = {opt for p in getattr(command, "params", ()) for opt in p.opts}
        grid = [f for f in ("--voxel-size", "--size") if f in flags]
        return " (try a coarser --voxel-size or a smaller --size)" if len(grid) == 2 else (
            f" (try a coarser {grid[0]})" if grid else "")

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
            code = code if isinstance(code, int) else 0
        except click.exceptions.NoArgsIsHelpError as exc:  # `kinfu`, `kinfu eval`: what the group offers, as --help
            click.echo(exc.ctx.get_help())
            code = 0
        except click.ClickException as exc:
            click.echo(f"kinfu: error: {_one_line(_usage_message(exc))}", err=True)
            code = exc.exit_code
        except (KeyboardInterrupt, click.Abort):
            click.echo("kinfu: interrupted", err=True)
            code = 130
        if standalone_mode:
            sys.exit(code)
        return code


@click.group(cls=_Main, modules=COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="kinfu")
def cli() -> None:
    """Robot spatial attention and next-best-view planning on recorded RGB-D data.

    Replays MCAP, ROS 1 .bag and ROS 2 bag recordings of a depth camera on a robot arm
    watching a tabletop, and answers: what does the scene look like, where did the person act,
    what is still unknown, and where should the camera look next.
    """


def main() -> int:
    """Run the CLI on sys.argv; returns the exit code (0, 2 for errors, 130 when interrupted)."""
    return cli.main(prog_name="kinfu", standalone_mode=False)


if __name__ == "__main__":
    sys.exit(main())
