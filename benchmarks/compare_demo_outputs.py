"""Compare two `make demo` output folders: JSON outputs equal except timing fields, other files byte-equal.

The renovation's proof that moving code changed no result: run the demo before and after a change and
compare. Timing fields (keys `seconds`, `seconds_per_view`, `timing_s`, `time_s`, and any key ending in
`_seconds`) are dropped before comparing; kinfu's ownership manifests are skipped; PNG plots are reported but not compared (matplotlib embeds
nothing variable, but fonts can differ between machines).

    python benchmarks/compare_demo_outputs.py OUT_BEFORE OUT_AFTER      # exit 1 on any difference
    python benchmarks/compare_demo_outputs.py --run OUT_BEFORE          # run the demo now, then compare
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

MANIFEST = ".kinfu-manifest.json"  # ownership records differ by file times
TIMING_KEYS = {"seconds", "seconds_per_view", "timing_s", "time_s"}


def strip_timing(obj: object) -> object:
    """`obj` without timing fields, at any depth."""
    if isinstance(obj, dict):
        return {k: strip_timing(v) for k, v in obj.items() if k not in TIMING_KEYS and not k.endswith("_seconds")}
    if isinstance(obj, list):
        return [strip_timing(v) for v in obj]
    return obj


def _first_difference(a: object, b: object, where: str = "") -> str | None:
    if type(a) is not type(b):
        return f"{where or '/'}: {type(a).__name__} vs {type(b).__name__}"
    if isinstance(a, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                return f"{where}/{k}: only in {'after' if k not in a else 'before'}"
            d = _first_difference(a[k], b[k], f"{where}/{k}")
            if d:
                return d
        return None
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{where}: {len(a)} vs {len(b)} items"
        for i, (x, y) in enumerate(zip(a, b)):
            d = _first_difference(x, y, f"{where}[{i}]")
            if d:
                return d
        return None
    return None if a == b else f"{where}: {a!r} vs {b!r}"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _rewrite_paths(obj: object, old: str, new: str) -> object:
    """Output paths written into the JSON name the output folder: compare them relative to it."""
    if isinstance(obj, dict):
        return {k: _rewrite_paths(v, old, new) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_rewrite_paths(v, old, new) for v in obj]
    if isinstance(obj, str):
        return obj.replace(old, new)
    return obj


def compare(before: Path, after: Path) -> list[str]:
    """One line per difference between the two output folders (empty when they agree)."""
    problems = []
    files_b = {p.relative_to(before) for p in before.rglob("*") if p.is_file() and p.name != MANIFEST}
    files_a = {p.relative_to(after) for p in after.rglob("*") if p.is_file() and p.name != MANIFEST}
    for rel in sorted(files_b ^ files_a):
        problems.append(f"{rel}: only in {'before' if rel in files_b else 'after'}")
    for rel in sorted(files_b & files_a):
        pb, pa = before / rel, after / rel
        if rel.suffix == ".json":
            jb = _rewrite_paths(strip_timing(json.loads(pb.read_text())), str(before), "OUT")
            ja = _rewrite_paths(strip_timing(json.loads(pa.read_text())), str(after), "OUT")
            diff = _first_difference(jb, ja)
            if diff:
                problems.append(f"{rel}: {diff}")
        elif rel.suffix != ".png" and _digest(pb) != _digest(pa):
            problems.append(f"{rel}: bytes differ")
    return problems


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path, nargs="?")
    ap.add_argument("--run", action="store_true", help="run the demo into a temporary folder as 'after'")
    a = ap.parse_args(argv)
    after = a.after
    if a.run:
        after = Path(tempfile.mkdtemp(prefix="kinfu-demo-"))
        repo = Path(__file__).resolve().parents[1]
        subprocess.run([sys.executable, "-m", "kinfu_cli.demo", "--data", str(repo / "sample_data"), "--out",
                        str(after)], check=True, cwd=repo, stdout=subprocess.DEVNULL)
    if after is None:
        ap.error("give AFTER or --run")
    problems = compare(a.before, after)
    for p in problems:
        print(p)
    n = sum(1 for _ in a.before.rglob("*.json"))
    print(f"{n} JSON outputs compared without timing fields, other files by bytes (PNG skipped): "
          f"{'identical' if not problems else f'{len(problems)} differences'}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
