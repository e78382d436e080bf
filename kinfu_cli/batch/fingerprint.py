"""When a stage's outputs are still current: its inputs' sizes and modification times, its options and the
kinfu version hashed together, and its outputs unchanged since they were recorded."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path

from kinfu_cli import __version__


def _stats(path: Path) -> list:
    """[relative name, size, mtime_ns] of a file, or of every file under a folder (ROS 2 bags)."""
    if path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file())
        return [[str(p.relative_to(path)), p.stat().st_size, p.stat().st_mtime_ns] for p in files]
    st = path.stat()
    return [[path.name, st.st_size, st.st_mtime_ns]]


def input_fingerprint(stage: str, inputs: Iterable[tuple[str, Path]], options: Mapping) -> str:
    """sha256 of the stage name, the inputs' stat (size + mtime), the options and the kinfu version.

    inputs: (label, path) pairs; the label (not the path) enters the hash, so an output folder moved or
    copied whole (stat kept) is still current."""
    doc = {"stage": stage, "version": __version__, "options": dict(options),
           "inputs": [[label, _stats(Path(p))] for label, p in inputs]}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def output_stats(outdir: Path, outputs: Iterable[str]) -> dict[str, list[int]] | None:
    """{relative path: [size, mtime_ns]} of the outputs, or None when one is missing."""
    out = {}
    for rel in outputs:
        try:
            st = os.stat(outdir / rel)
        except OSError:
            return None
        out[rel] = [st.st_size, st.st_mtime_ns]
    return out
