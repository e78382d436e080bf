"""Compile numba's kernels once before the test workers start, split over two processes.

numba caches compiled kernels beside their source, keyed by the source file's path and time: a fresh
checkout (CI) compiles every kernel, and with two xdist workers each compiles the same kernels for
itself. Running the stages once on a few sample frames, fusion/tracking in one process and
planning/segmentation/simulation in the other, fills the cache in about half that time; the workers then
load the kernels. On a warm cache this costs a few seconds. A failure here only means the workers compile
as before: the tests themselves judge the code.

Run by tests/conftest.py (the xdist controller, before the workers start); `python tests/warm_kernels.py`
runs it by hand.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
REC = REPO / "sample_data" / "tabletop" / "recording.mcap"
GT = REPO / "sample_data" / "tabletop" / "ground_truth"


def _jobs(out: Path) -> dict[str, list[list[str]]]:
    fuse = ["fuse", str(REC), "--resolution", "64", "--quiet", "--force"]
    return {
        "fusion": [
            fuse + ["-o", str(out / "icp"), "--pose", "icp", "--color", "mode", "--end", "3", "--max-lost", "1"],
            ["poi", str(REC), "-o", str(out / "zvc.json"), "--algorithm", "zvc", "--force"],
            # kernels the two jobs above did not reach, compiled by several test files (each worker compiled them
            # for itself): the shadow filter, the simulator's shading, MUPF's filter and distance field
            fuse + ["-o", str(out / "shadow"), "--shadow-filter", "--end", "2"],
            ["synth", "-o", str(out / "synth"), "--frames", "2", "--width", "32", "--height", "24", "--formats",
             "mcap", "--quiet"],
            ["eval", "localize", "--shapes", "tetrahedron", "--trials", "1", "--particles", "60",
             "--recognition-trials", "0", "--quiet", "-o", str(out / "localize.json")],
        ],
        "planning": [
            fuse + ["-o", str(out / "scan")],
            ["poi", str(REC), "-o", str(out / "pois.json"), "--force"],
            ["nbv", str(out / "scan" / "volume.npz"), "--pois", str(out / "pois.json"), "--clear", "--top", "3",
             "-o", str(out / "views.json"), "--quiet", "--force"],
            ["nbv", str(out / "scan" / "volume.npz"), "--mode", "objects", "-o", str(out / "oviews.json"),
             "--quiet", "--force"],
            ["segment", str(out / "scan" / "volume.npz"), "-o", str(out / "seg"), "--quiet", "--force"],
            ["eval", "fusion", str(out / "scan"), "--ground-truth", str(GT), "-o", str(out / "ef.json"),
             "--quiet", "--force"],
            ["eval", "nbv", str(GT), "--views", "1", "--strategy", "poi,random", "--width", "80", "--height", "60",
             "-o", str(out / "en.json"), "--quiet", "--force"],
        ],
    }


def _run_job(commands: list[list[str]]) -> None:
    from click.testing import CliRunner

    from kinfu_cli.cli import cli

    for args in commands:
        CliRunner().invoke(cli, args)


def cache_is_warm() -> bool:
    """True when every source file with a numba kernel has cache entries newer than itself (a rough test: a
    kernel never run before is still compiled by the worker that needs it)."""
    for src in (REPO / "kinfu_cli").rglob("*.py"):
        if "njit" not in src.read_text(errors="ignore"):
            continue
        index = list(src.parent.glob(f"__pycache__/{src.stem}.*.nbi"))
        if not index or max(p.stat().st_mtime for p in index) < src.stat().st_mtime:
            return False
    return True


def warm(timeout_s: float = 600) -> None:
    """Both jobs in parallel subprocesses; returns when they end (errors are ignored, see the docstring)."""
    if not REC.exists() or cache_is_warm():
        return
    with tempfile.TemporaryDirectory(prefix="kinfu-warm-") as tmp:
        procs = [subprocess.Popen([sys.executable, __file__, name, tmp], cwd=REPO, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL) for name in ("fusion", "planning")]
        for p in procs:
            try:
                p.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                p.kill()


if __name__ == "__main__":
    if len(sys.argv) == 3:
        sys.path.insert(0, str(REPO))
        _run_job(_jobs(Path(sys.argv[2]))[sys.argv[1]])
    else:
        warm()
