"""What an output option's path may name: the kind of file or folder the command writes there.

Refused before any work, because the writers would otherwise write what the option holds under any name: `poi
--plot p.json` wrote a PNG named p.json, `poi -o -` a JSON file named '-', `synth -o x.mcap` and `import -o x.txt`
folders named like files. A suffix decides only where it names another kind of file (a JSON results file may be
called results.txt; a folder may have a dot in its name).
"""

from __future__ import annotations

import os
from pathlib import Path

import click

from kinfu_cli.core.file_kinds import (FILE_SUFFIXES, GEOMETRY_SUFFIXES, IMAGE_SUFFIXES, OTHER_FILE_SUFFIXES,
                                       RECORDING_SUFFIXES)

KINDS = ("json", "image", "viewer", "geometry", "folder", "recording", "trajectory")


def output_kind_problem(path: str | os.PathLike, kind: str) -> str | None:
    """Why `path` cannot hold an output of `kind` (one of KINDS), or None. An existing folder given where a file
    is written is left to the command (some take a folder there) and to claim_output."""
    if kind not in KINDS:
        raise ValueError(f"output kind {kind!r}: expected one of {', '.join(KINDS)}")
    text = os.fspath(path)
    if text == "-":
        return "'-' (standard output) is not a path kinfu writes to"
    p = Path(text)
    suffix = p.suffix.lower()
    if kind not in ("folder", "recording") and p.is_dir():
        return None
    if kind == "image" and suffix and suffix not in IMAGE_SUFFIXES:
        return f"{text} does not name an image; expected FILE.png (or .pdf, .svg, .jpg)"
    if kind == "viewer" and suffix != ".mcap":
        return f"{text}: the viewer file is an MCAP; expected FILE.mcap"
    if kind == "geometry" and suffix not in GEOMETRY_SUFFIXES:
        return f"{text}: expected a mesh or point cloud file, FILE.ply (or .obj, .stl, .pcd)"
    if kind == "json" and suffix in OTHER_FILE_SUFFIXES:
        return f"{text} names a {suffix} file; the results are JSON: expected FILE.json"
    if kind == "trajectory" and suffix in OTHER_FILE_SUFFIXES - {".tum", ".csv"} | {".json"}:
        return f"{text} names a {suffix} file; the trajectory is TUM text: expected FILE.tum (or .txt)"
    if kind == "folder" and suffix in FILE_SUFFIXES:
        return f"{text} names a {suffix} file; this output is a folder: name it without that suffix"
    if kind == "recording" and suffix not in RECORDING_SUFFIXES and suffix in FILE_SUFFIXES:
        return (f"{text} names a {suffix} file; expected NAME.mcap, NAME.bag, or a folder name (a ROS 2 bag) "
                f"without that suffix")
    return None


class OutputPath(click.Path):
    """click.Path for an output option (a pathlib.Path by default), refusing an empty value (click would make ''
    into Path('.'), and the error would speak of the current folder) and '-' (pointing to --json where the command
    has it). `kind` (one of KINDS; None: any) is what the option writes: claim_outputs refuses a name of another
    kind of file, before any work."""

    def __init__(self, *args, kind: str | None = None, path_type=Path, **kwargs) -> None:
        if kind is not None and kind not in KINDS:
            raise ValueError(f"output kind {kind!r}: expected one of {', '.join(KINDS)}")
        self.kind = kind
        super().__init__(*args, path_type=path_type, **kwargs)

    def convert(self, value, param, ctx):
        if isinstance(value, (str, bytes)) and not value.strip():
            self.fail("expected a path, got an empty one", param, ctx)
        if isinstance(value, (str, os.PathLike)) and os.fspath(value) == "-":
            problem = output_kind_problem(value, "json")
            if ctx is not None and any(p.name == "as_json" for p in ctx.command.params):
                problem += "; --json prints the results on standard output"
            self.fail(problem, param, ctx)
        return super().convert(value, param, ctx)


def output_kind_of(name: str) -> str | None:
    """The kind (KINDS) of the running command's output option of Python name `name`, None when it has none:
    claim_outputs checks it after the input and ownership checks, whose errors say more (`localize -o
    seg/segments.ply` is an input read beside segments.json before it is a JSON result misnamed)."""
    ctx = click.get_current_context(silent=True)
    for p in (ctx.command.params if ctx is not None else []):
        if p.name == name and isinstance(p.type, OutputPath):
            return p.type.kind
    return None
