"""How commands hand results over: a JSON file (-o), JSON on stdout (--json) or a printed table."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterable

import click

from kinfu_cli.core.atomic import write_json

#: --quiet of the eval commands, as fuse, segment and poi have it
QUIET_HELP = "Only warnings and errors: no progress bar, no tables (--json still prints the JSON)."


#: click context meta key: the command line's warnings about options without effect (_options.check_inapplicable),
#: printed before any work
OPTION_WARNINGS = "kinfu.option_warnings"


def option_warnings() -> list[str]:
    """This command's warnings about options without effect (printed already)."""
    ctx = click.get_current_context(silent=True)
    return list(ctx.meta.get(OPTION_WARNINGS, ())) if ctx is not None else []


def option_warnings_first(warnings: list[str]) -> list[str]:
    """The command line's warnings about options without effect, then `warnings` (without those): a report read
    later says which options the run did not use, as its stderr did."""
    said = option_warnings()
    return said + [w for w in warnings if w not in said]


def with_option_warnings(doc: dict) -> dict:
    """`doc` (a result document with a "warnings" list) with option_warnings_first as its warnings."""
    if isinstance(doc.get("warnings"), list):
        doc["warnings"] = option_warnings_first(doc["warnings"])
    return doc


def print_warnings(doc: dict) -> None:
    """Each entry of doc["warnings"] as one `kinfu: warning: ...` line on stderr (also with --quiet / --json),
    but those about options without effect: they were printed before the work."""
    said = set(option_warnings())
    for w in doc.get("warnings") or []:
        if w not in said:
            click.echo(f"kinfu: warning: {w}", err=True)


def emit(doc: dict, output, as_json: bool, lines_of: Callable[[dict], Iterable[str]], quiet: bool = False) -> None:
    """Write `doc` atomically to `output` when given; print it as JSON or as the lines `lines_of` makes (quiet:
    only its warnings, as QUIET_HELP says); the command line's warnings about options without effect go first
    into its warnings."""
    with_option_warnings(doc)
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
