"""The `kinfu` click group. Thin: sub-commands live in kinfu_cli/commands/ and call library code.

A module in kinfu_cli/commands/ is added when it defines `command` (a click.Command); with
`group = "eval"` it goes under `kinfu eval`. Nothing is registered that does not work yet.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import click

from kinfu_cli import __version__, commands
from kinfu_cli.errors import KinfuError


def _discover() -> tuple[list[click.Command], dict[str, list[click.Command]]]:
    top: list[click.Command] = []
    groups: dict[str, list[click.Command]] = {}
    for mod_info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        mod = importlib.import_module(f"{commands.__name__}.{mod_info.name}")
        cmd = getattr(mod, "command", None)
        if not isinstance(cmd, click.Command):
            continue
        group = getattr(mod, "group", None)
        if group:
            groups.setdefault(group, []).append(cmd)
        else:
            top.append(cmd)
    return top, groups


class _Main(click.Group):
    def invoke(self, ctx: click.Context):  # one-line errors, exit 2, no traceback
        try:
            return super().invoke(ctx)
        except KinfuError as exc:
            click.echo(f"kinfu: error: {exc}", err=True)
            ctx.exit(exc.exit_code)
        except MemoryError:
            click.echo("kinfu: error: out of memory (try a coarser --voxel-size or smaller --size)", err=True)
            ctx.exit(2)
        except OSError as exc:
            where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
            click.echo(f"kinfu: error: {where}{exc.strerror or exc}", err=True)
            ctx.exit(2)


@click.group(cls=_Main, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="kinfu")
def cli() -> None:
    """Robot spatial attention and next-best-view planning on recorded RGB-D data.

    Replays MCAP, ROS 1 .bag and ROS 2 bag recordings of a depth camera on a robot arm
    watching a tabletop, and answers: what does the scene look like, where did the person act,
    what is still unknown, and where should the camera look next.
    """


def _build() -> click.Group:
    top, groups = _discover()
    for cmd in top:
        cli.add_command(cmd)
    for name, cmds in groups.items():
        grp = click.Group(name=name, help=f"Score against ground truth: {', '.join(c.name for c in cmds)}.",
                          short_help="Score results against ground truth, tables like the papers'.")
        for cmd in cmds:
            grp.add_command(cmd)
        cli.add_command(grp)
    return cli


_build()


def main() -> None:
    cli.main(prog_name="kinfu")


if __name__ == "__main__":
    sys.exit(main())
