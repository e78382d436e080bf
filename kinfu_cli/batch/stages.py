"""What the engine knows about a stage: its name, the stages it needs, the files it reads and writes.

The engine is generic: the caller hands it a table of `StageSpec` (the command line builds it from the
commands themselves, so a batch stage writes exactly what the single command writes). Paths are relative to
the recording's output folder; RECORDING stands for the recording itself, "<name>" for the plan recording's
link `name` (a path the plan resolves: the `before` volume of diff, the `ground_truth` folder of the evaluations,
the combined `viz` file). Inputs, outputs and claims are tuples, or functions of the plan recording when they
depend on its stages (the viewer file combines the viewer files of the stages the recording has).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

RECORDING = "<recording>"


@dataclass(frozen=True)
class StageRun:
    """What a finished stage reports: a few key numbers and its warnings."""

    numbers: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


def _per(value, rec) -> tuple[str, ...]:
    return tuple(value(rec)) if callable(value) else tuple(value)


@dataclass(frozen=True)
class StageSpec:
    """One stage. `check(rec, options)` raises KinfuError for bad options before any work; `run(rec, options,
    force)` does the work (module-level functions: they travel to workers by reference); `rec` is the plan's
    PlanRecording (path, output folder, stages, links). `claims`: the paths it writes (checked for ownership
    before any work); `outputs`: files whose presence and stat say the stage is complete; `inputs`: what its
    fingerprint covers; `needs`: stages of the same recording it runs after (the plan must list them);
    `wants`: stages it runs after when the recording has them (it reads their outputs if present);
    `links`: the plan recording links it needs (the plan checks they resolve); `file_options`: its options whose
    value is an input file (relative to the plan's folder, part of the fingerprint); `extras`: (option, file) of
    the files it writes only when that option is true (plots, viewer files), removed with its outputs but not
    claimed up front; `reads_others`: stages of another recording of the plan whose outputs a link of it may name
    (diff's `before`: another recording's fuse)."""

    name: str
    needs: tuple[str, ...]
    inputs: tuple[str, ...] | Callable
    outputs: tuple[str, ...] | Callable
    claims: tuple[str, ...] | Callable
    check: Callable[[Any, Mapping], None]
    run: Callable[[Any, Mapping, bool], StageRun]
    wants: tuple[str, ...] = ()
    links: tuple[str, ...] = ()
    file_options: tuple[str, ...] = ()  # options naming an input file (the plan resolves them against its folder)
    extras: tuple[tuple[str, str], ...] = ()  # (option, file) written only when it is true: ("plot", "views.png")
    reads_others: tuple[str, ...] = ()  # another recording's stages a link may name (diff's before: its fuse)

    def input_paths(self, rec) -> list[tuple[str, Path]]:
        """(label, path) of each input: RECORDING is the recording, "<link>" a link of the plan recording, the
        others are in its output folder; then the files the stage's file options name."""
        opts = rec.stage_options(self.name)
        out = [(f"--{k}", Path(opts[k])) for k in self.file_options if isinstance(opts.get(k), str)]
        for p in _per(self.inputs, rec):
            if p == RECORDING:
                out.append((p, rec.path))
            elif p.startswith("<") and p.endswith(">"):
                out.append((p, rec.links[p[1:-1]]))
            else:
                out.append((p, rec.output / p))
        return out

    def outputs_of(self, rec) -> tuple[str, ...]:
        return _per(self.outputs, rec)

    def claims_of(self, rec) -> tuple[str, ...]:
        return _per(self.claims, rec)

    def extra_files(self, options: Mapping | None = None) -> tuple[str, ...]:
        """Its extras (every one; with `options`, those the options ask for: their option is true)."""
        return tuple(f for opt, f in self.extras if options is None or options.get(opt) is True)


def stage_dependents(table: Mapping[str, StageSpec]) -> dict[str, list[str]]:
    """stage -> the stages of the table that read its outputs (they need or want it), directly or through others,
    in the table's order."""
    out: dict[str, list[str]] = {name: [] for name in table}
    for name in reversed(list(table)):  # a stage's dependents are complete before the stages it reads
        for before in (*table[name].needs, *table[name].wants):
            if before in out:
                out[before] += [s for s in (name, *out[name]) if s not in out[before]]
    return {name: [s for s in table if s in later] for name, later in out.items()}


def stage_order(table: Mapping[str, StageSpec], wanted: list[str]) -> list[str]:
    """`wanted` in the table's order (a dependency comes before what needs it)."""
    return [name for name in table if name in wanted]
