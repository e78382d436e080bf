"""How commands hand results over: a JSON file (-o), JSON on stdout (--json) or a printed table."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterable

import click

from kinfu_cli.core.atomic import write_json

#: --quiet of the eval commands, as fuse, segment and poi have it
QUIET_HELP = "Only warnings and errors: no progress bar, no tables (--json still prints the JSON)."


def print_warnings(doc: dict) -> None:
    """Each entry of doc["warnings"] as one `kinfu: warning: ...` line on stderr (also with --quiet / --json)."""
    for w in doc.get("warnings") or []:
        click.echo(f"kinfu: warning: {w}", err=True)


def emit(doc: dict, output, as_json: bool, lines_of: Callable[[dict], Iterable[str]], quiet: bool = False) -> None:
    """Write `doc` atomically to `output` when given; print it as JSON or as the lines `lines_of` makes (quiet:
    only its warnings, as QUIET_HELP says)."""
    print_warnings(doc)
    if output is not None:
        write_json(output, doc)
    if as_json:
        click.echo(json.dumps(doc, indent=2, default=float))
    elif not quiet:
        for line in lines_of(doc):
            click.echo(line)
        if output is not None:
            click.echo(f"wrote {output}")
    sys.stdout.flush()
