"""The batch plan: which recordings go through which stages with which options (TOML or YAML).

    output = "out/batch"                      # optional: the command line's output wins
    stages = ["fuse", "poi", "nbv", "segment"]
    recordings = ["sessions/*.mcap", {path = "lab/day2.bag", output = "day2", options = {fuse = {end = 6}}}]
    [options.fuse]
    voxel-size = 0.02

Paths are relative to the plan file. Everything is checked before any work: unknown keys or stages, a
stage without the stages it needs, a path that does not exist or a glob that matches nothing, and two
recordings that would write to the same output folder are one-line errors naming the plan entry.
"""

from __future__ import annotations

import glob
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.batch.stages import StageSpec

_TOP_KEYS = {"output", "stages", "options", "recordings"}
_ENTRY_KEYS = {"path", "output", "options"}


@dataclass(frozen=True)
class PlanRecording:
    """One recording of the plan: where it is, its output folder, its options per stage, its plan entry."""

    path: Path
    output: Path
    options: dict[str, dict]
    entry: str

    def stage_options(self, stage: str) -> dict:
        return self.options.get(stage, {})


@dataclass(frozen=True)
class Plan:
    source: Path
    output: Path
    stages: list[str]
    recordings: list[PlanRecording] = field(default_factory=list)


def _fail(source: Path, where: str, what: str) -> ConfigError:
    return ConfigError(f"{source}: {where}: {what}")


def _read(source: Path) -> dict:
    try:
        text = source.read_text()
    except OSError as exc:
        raise ConfigError(f"{source}: cannot read the plan ({exc.strerror})") from None
    suffix = source.suffix.lower()
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{source}: not valid TOML ({exc})") from None
    elif suffix in (".yaml", ".yml"):
        import yaml  # PyYAML comes with dask

        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{source}: not valid YAML ({' '.join(str(exc).split())})") from None
    else:
        raise ConfigError(f"{source}: expected a .toml, .yaml or .yml plan")
    if not isinstance(doc, dict):
        raise ConfigError(f"{source}: expected a table/mapping at the top")
    return doc


def _normalise_options(source: Path, where: str, value, table: Mapping[str, StageSpec]) -> dict[str, dict]:
    """{stage: {option-name: value}} with option names in their flag spelling (voxel_size -> voxel-size)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _fail(source, where, "expected a table of stages")
    out = {}
    for stage, opts in value.items():
        if stage not in table:
            raise _fail(source, f"{where}.{stage}", f"unknown stage (known: {', '.join(table)})")
        if not isinstance(opts, dict):
            raise _fail(source, f"{where}.{stage}", "expected a table of options")
        out[stage] = {str(k).replace("_", "-"): v for k, v in opts.items()}
    return out


def _expand(source: Path, where: str, pattern: str) -> list[Path]:
    base = source.parent
    full = os.path.normpath(pattern if os.path.isabs(pattern) else base / pattern)
    if glob.has_magic(pattern):
        found = sorted(Path(p) for p in glob.glob(full, recursive=True))
        if not found:
            raise _fail(source, where, f"{pattern!r} matches nothing")
        return found
    if not Path(full).exists():
        raise _fail(source, where, f"{pattern}: no such file or folder")
    return [Path(full)]


def _default_output(source: Path, path: Path) -> Path:
    """The recording's path relative to the plan without its suffix (sessions/day1.mcap -> sessions/day1);
    a recording outside the plan's folder: its name without suffix."""
    try:
        rel = Path(os.path.abspath(path)).relative_to(os.path.abspath(source.parent))
    except ValueError:
        rel = Path(path.name)
    return rel.with_suffix("") if rel.suffix else rel


def _recordings(source: Path, doc: dict, output: Path, table) -> list[PlanRecording]:
    entries = doc.get("recordings")
    if isinstance(entries, str):
        entries = [entries]
    if not isinstance(entries, list) or not entries:
        raise _fail(source, "recordings", "expected a non-empty list of paths, globs or {path, output, options}")
    out: list[PlanRecording] = []
    for i, e in enumerate(entries):
        where = f"recordings[{i}]"
        if isinstance(e, str):
            e = {"path": e}
        if not isinstance(e, dict) or not isinstance(e.get("path"), str):
            raise _fail(source, where, "expected a path or glob, or a table with 'path'")
        if unknown := set(e) - _ENTRY_KEYS:
            raise _fail(source, where, f"unknown key(s) {', '.join(sorted(unknown))} (known: path, output, options)")
        paths = _expand(source, where, e["path"])
        if e.get("output") is not None and len(paths) > 1:
            raise _fail(source, where, f"'output' names one folder but {e['path']!r} matches {len(paths)} recordings")
        opts = _normalise_options(source, f"{where}.options", e.get("options"), table)
        for p in paths:
            rel = Path(str(e["output"])) if e.get("output") is not None else _default_output(source, p)
            if rel.is_absolute() or ".." in rel.parts or str(rel) in ("", "."):
                raise _fail(source, where, f"output {str(rel)!r}: expected a folder name inside the output folder")
            out.append(PlanRecording(path=p, output=output / rel, options=opts, entry=f"{where} {p}"))
    seen: dict[Path, PlanRecording] = {}
    for r in out:
        key = Path(os.path.normpath(r.output))
        if key in seen:
            raise _fail(source, r.entry.split(" ")[0],
                        f"{r.path} and {seen[key].path} ({seen[key].entry.split(' ')[0]}) would both write to "
                        f"{r.output}; give one of them an 'output'")
        seen[key] = r
    return out


def load_plan(source: str | os.PathLike, table: Mapping[str, StageSpec], output: str | os.PathLike | None = None,
              ) -> Plan:
    """Read and check the plan at `source` against the stage table; `output` overrides the plan's."""
    source = Path(source)
    doc = _read(source)
    if unknown := set(doc) - _TOP_KEYS:
        raise _fail(source, ", ".join(sorted(unknown)), f"unknown key(s) (known: {', '.join(sorted(_TOP_KEYS))})")
    stages = doc.get("stages")
    if isinstance(stages, str):
        stages = [stages]
    if not isinstance(stages, list) or not stages or not all(isinstance(s, str) for s in stages):
        raise _fail(source, "stages", f"expected a non-empty list of stage names ({', '.join(table)})")
    for s in stages:
        if s not in table:
            raise _fail(source, "stages", f"unknown stage {s!r} (known: {', '.join(table)})")
        if missing := [n for n in table[s].needs if n not in stages]:
            raise _fail(source, "stages", f"{s} needs {', '.join(missing)}: add it to the list")
    if len(set(stages)) != len(stages):
        raise _fail(source, "stages", "a stage is listed twice")
    if output is None:
        if not isinstance(doc.get("output"), str) or not doc["output"].strip():
            raise _fail(source, "output", "no output folder: give 'output' in the plan or on the command line")
        out = Path(doc["output"])
        out = out if out.is_absolute() else Path(os.path.normpath(source.parent / out))
    else:
        out = Path(output)
    common = _normalise_options(source, "options", doc.get("options"), table)
    recs = _recordings(source, doc, out, table)
    merged = [PlanRecording(r.path, r.output, {s: {**common.get(s, {}), **r.options.get(s, {})} for s in stages},
                            r.entry) for r in recs]
    return Plan(source=source, output=out, stages=[s for s in table if s in stages], recordings=merged)
