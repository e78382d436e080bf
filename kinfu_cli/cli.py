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
from kinfu_cli.commands._options import PARAMETER_FLAGS
from kinfu_cli.core.errors import KinfuError

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
    "eval": {"poi": "eval_poi", "fusion": "eval_fusion", "nbv": "eval_nbv"},
}


class _LazyGroup(click.Group):
    """A group whose sub-commands are imported from their modules when first used."""

    def __init__(self, *args, modules: dict[str, str | dict[str, str]], **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.modules = modules
        self.last_resolved: click.Command | None = None  # the sub-command being run, for error messages

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(self.modules)

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
            cmd = importlib.import_module(f"kinfu_cli.commands.{target}").command
        self.commands[name] = self.last_resolved = cmd
        return cmd


def _flags_of(parameter: str, group: _LazyGroup) -> str:
    """The command-line flag(s) of a library parameter name ("a/b" for two) in the command being run:
    PARAMETER_FLAGS first, else its option of that Python name, else the name as the library gave it."""
    cmd: click.Command | None = group
    while isinstance(cmd, _LazyGroup):
        cmd = cmd.last_resolved
    options = {p.name: max(p.opts, key=len) for p in (cmd.params if cmd else []) if isinstance(p, click.Option)}
    return "/".join(PARAMETER_FLAGS.get(n) or options.get(n) or n for n in parameter.split("/"))


class _Main(_LazyGroup):
    def invoke(self, ctx: click.Context):  # one-line errors, exit 2, no traceback
        try:
            return super().invoke(ctx)
        except KinfuError as exc:
            message = f"{_flags_of(exc.parameter, self)}: {exc.detail}" if exc.parameter else str(exc)
            click.echo(f"kinfu: error: {message}", err=True)
            ctx.exit(exc.exit_code)
        except MemoryError:
            click.echo("kinfu: error: out of memory (try a coarser --voxel-size or smaller --size)", err=True)
            ctx.exit(2)
        except OSError as exc:
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            click.echo(f"kinfu: error: {where}{exc.strerror or exc}", err=True)
            ctx.exit(2)


@click.group(cls=_Main, modules=COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="kinfu")
def cli() -> None:
    """Robot spatial attention and next-best-view planning on recorded RGB-D data.

    Replays MCAP, ROS 1 .bag and ROS 2 bag recordings of a depth camera on a robot arm
    watching a tabletop, and answers: what does the scene look like, where did the person act,
    what is still unknown, and where should the camera look next.
    """


def main() -> None:
    cli.main(prog_name="kinfu")


if __name__ == "__main__":
    sys.exit(main())
