"""What the engine knows about a stage: its name, the stages it needs, the files it reads and writes.

The engine is generic: the caller hands it a table of `StageSpec` (the command line builds it from the
commands themselves, so a batch stage writes exactly what the single command writes). Paths are relative to
the recording's output folder; RECORDING stands for the recording itself.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

RECORDING = "<recording>"


@dataclass(frozen=True)
class StageRun:
    """What a finished stage reports: a few key numbers and its warnings."""

    numbers: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)


@dataclass(frozen=True)
class StageSpec:
    """One stage. `check(recording, outdir, options)` raises KinfuError for bad options before any work;
    `run(recording, outdir, options, force)` does the work (module-level functions: they travel to workers
    by reference). `claims`: the paths it writes (checked for ownership before any work); `outputs`: files
    whose presence and stat say the stage is complete; `inputs`: what its fingerprint covers."""

    name: str
    needs: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    claims: tuple[str, ...]
    check: Callable[[Path, Path, Mapping], None]
    run: Callable[[Path, Path, Mapping, bool], StageRun]

    def input_paths(self, recording: Path, outdir: Path) -> list[tuple[str, Path]]:
        """(label, path) of each input: RECORDING is the recording, the others are in its output folder."""
        return [(p, recording if p == RECORDING else outdir / p) for p in self.inputs]


def stage_order(table: Mapping[str, StageSpec], wanted: list[str]) -> list[str]:
    """`wanted` in the table's order (a dependency comes before what needs it)."""
    return [name for name in table if name in wanted]
