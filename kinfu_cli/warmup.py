"""`python -m kinfu_cli.warmup`: compile kinfu's numba kernels once, at set-up, instead of in the user's first run.

numba compiles a kernel the first time it is called and caches the machine code beside its module (`cache=True`,
keyed by the source file's path and time). A fresh install therefore paid 40-60 s of compilation inside the first
real command: `kinfu fuse --pose icp` on the 60 7-Scenes kitchen frames took 51 s cold against 8 s warm (1.2 fps
against 7.7), a cold `make demo` 86 s against 28 s. This runs the commands that own the kernels on a few frames of
the bundled sample recording (a coarse grid: the kernels' argument types do not depend on its size), in two
processes side by side (fusion and tracking; planning, segmentation and evaluation), into a temporary folder it
removes, and calls the library kernels no command reaches there (api_kernels, reader_kernels). A kernel called
with other argument types (an int32 where it had an int64, a read-only or non-contiguous array) is compiled again:
the callers pass one set of types. `make` runs it once after installing, and the test session before its workers
start (tests/conftest.py), so that they load the kernels instead of each compiling them. It writes nothing but
numba's cache.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_data" / "tabletop"
KERNEL = re.compile(r"^@(numba\.)?njit", re.MULTILINE)  # a source file that defines numba kernels
# kernels no command runs (the benchmarks' brute-force reference): not compiled here, and not waited for
NOT_WARMED = {Path("nbv", "reference.py")}


def jobs(rec: Path, gt: Path, out: Path) -> dict[str, list[list[str]]]:
    """The kinfu command lines of each job; together they reach every kernel the pipeline runs."""
    fuse = ["fuse", str(rec), "--resolution", "64", "--quiet", "--force"]
    return {
        "fusion": [
            fuse + ["-o", str(out / "icp"), "--pose", "icp", "--color", "mode", "--end", "3", "--max-lost", "1"],
            ["poi", str(rec), "-o", str(out / "zvc.json"), "--algorithm", "zvc", "--force"],
            fuse + ["-o", str(out / "shadow"), "--shadow-filter", "--end", "2"],
            ["synth", "-o", str(out / "synth"), "--frames", "2", "--width", "32", "--height", "24", "--formats",
             "mcap", "--quiet"],
            ["eval", "localize", "--shapes", "tetrahedron", "--trials", "1", "--particles", "60",
             "--recognition-trials", "0", "--quiet", "-o", str(out / "localize.json")],
        ],
        "planning": [
            fuse + ["-o", str(out / "scan")],
            ["poi", str(rec), "-o", str(out / "pois.json"), "--force"],
            ["nbv", str(out / "scan" / "volume.npz"), "--pois", str(out / "pois.json"), "--clear", "--top", "3",
             "-o", str(out / "views.json"), "--quiet", "--force"],
            ["nbv", str(out / "scan" / "volume.npz"), "--mode", "objects", "-o", str(out / "oviews.json"),
             "--quiet", "--force"],
            ["segment", str(out / "scan" / "volume.npz"), "-o", str(out / "seg"), "--quiet", "--force"],
            ["eval", "fusion", str(out / "scan"), "--ground-truth", str(gt), "-o", str(out / "ef.json"),
             "--quiet", "--force"],
            ["eval", "nbv", str(gt), "--views", "1", "--strategy", "poi,random", "--width", "80", "--height", "60",
             "-o", str(out / "en.json"), "--quiet", "--force"],
        ],
    }


def reader_kernels() -> tuple[bool, int]:
    """The readers' kernels the sample recording does not need: RVL depth (ROS 2's compressedDepth rvl) and colour
    from another camera (a RealSense without alignment), called as the readers call them, on a 4x3 image (the colour
    camera at the depth camera's place). Returns (the RVL round trip gave the image back, pixels coloured)."""
    import numpy as np

    from kinfu_cli.io.color_registration import ColorRegistration, register_color
    from kinfu_cli.io.rvl import decode_rvl, encode_rvl
    from kinfu_cli.io.undistort import Undistorter

    depth_mm = np.full((3, 4), 1000, dtype=np.uint16)
    same = bool(np.array_equal(decode_rvl(encode_rvl(depth_mm))[0], depth_mm))
    K = np.array([[4.0, 0, 2], [0, 4, 1.5], [0, 0, 1]])
    reg = ColorRegistration("project", lens=Undistorter.pinhole(K), color_size=(4, 3), T_color_depth=np.eye(4))
    _, mask = register_color(reg, depth_mm / np.float32(1000), K, np.full((3, 4, 3), 9, np.uint8), "warmup")
    return same, int(depth_mm.size if mask is None else np.count_nonzero(mask))


def api_kernels() -> tuple[int, int]:
    """The library kernels no command reaches on the sample: the per-ray caster behind `nbv.raycast.knowledge_map`
    and `cast_rays` (the tests' and benchmarks' reference for the batched caster: ~30 s to compile, once in each
    test worker before), and the whole-ray model cast of `TernaryVolume.raycast` (tracking's re-localisation), on a
    4^3 grid with one occupied voxel and a 16 cm volume that saw a wall 0.5 m away. Returns (how many of 4 rays hit
    the voxel, model pixels on the wall)."""
    import numpy as np

    from kinfu_cli.core.grid import EMPTY, OCCUPIED, TernaryGrid
    from kinfu_cli.fusion.volume import TernaryVolume
    from kinfu_cli.nbv.raycast import CLS_OCCUPIED, RayVolume, cast_rays

    labels = np.full((4, 4, 4), EMPTY, np.int8)
    labels[2, 2, 2] = OCCUPIED
    vol = RayVolume.from_grid(TernaryGrid(labels, np.zeros(3), 0.1))
    dirs = np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [-1.0, 0, 0]])
    hit = cast_rays(vol, np.array([0.01, 0.25, 0.25]), dirs, center=(0.25, 0.25, 0.25), radius=0.1, through=True)
    K = np.array([[40.0, 0, 3.5], [0, 40.0, 2.5], [0, 0, 1]])  # 10 x 7.5 cm of the wall: inside the volume
    tsdf = TernaryVolume(size=0.16, voxel_size=0.01, origin=(-0.08, -0.08, 0.42), truncation=0.03, min_depth=0.1)
    tsdf.integrate(np.full((6, 8), 0.5, np.float32), K, np.eye(4))
    depth, _, _ = tsdf.raycast(K, 8, 6, np.eye(4))
    return int(np.count_nonzero(hit.cls == CLS_OCCUPIED)), int(np.count_nonzero(np.abs(depth - 0.5) < 0.01))


def run_job(commands: list[list[str]]) -> list[str]:
    """Runs the commands in this process; for each that failed, the last line it said."""
    from click.testing import CliRunner

    from kinfu_cli.cli import cli

    failed = []
    for args in commands:
        res = CliRunner().invoke(cli, args)
        if res.exit_code != 0:
            said = (res.output.strip().splitlines() or [repr(res.exception)])[-1]
            failed.append(f"kinfu {args[0]}: {said}")
    return failed


def cache_folder(src: Path) -> Path:
    """Where numba caches the kernels of a source file: its __pycache__, or under NUMBA_CACHE_DIR (kinfu_cli/__init__
    sets it when the install folder cannot be written), in numba's sub-folder for the source's folder."""
    if not os.environ.get("NUMBA_CACHE_DIR"):
        return src.parent / "__pycache__"
    from numba.core.caching import _CacheLocator

    return Path(os.environ["NUMBA_CACHE_DIR"], _CacheLocator.get_suitable_cache_subpath(str(src)))


def cache_is_warm() -> bool:
    """True when every source file with a numba kernel has cache entries newer than itself (a rough test: a
    kernel never run before is still compiled by its first caller)."""
    for src in (REPO / "kinfu_cli").rglob("*.py"):
        if src.relative_to(REPO / "kinfu_cli") in NOT_WARMED or not KERNEL.search(src.read_text(errors="ignore")):
            continue
        index = list(cache_folder(src).glob(f"{src.stem}.*.nbi"))
        if not index or max(p.stat().st_mtime for p in index) < src.stat().st_mtime:
            return False
    return True


def warm(sample: Path = SAMPLE, timeout_s: float = 900, check_cache: bool = True) -> list[str]:
    """Both jobs in parallel subprocesses, unless the cache is warm already (check_cache False: the caller has just
    looked); returns what failed ([] when all ran, or when there is no sample recording to run on)."""
    rec = sample / "recording.mcap"
    if not rec.exists() or (check_cache and cache_is_warm()):
        return []
    failed = []
    with tempfile.TemporaryDirectory(prefix="kinfu-warmup-") as tmp:
        procs = {name: subprocess.Popen([sys.executable, "-m", "kinfu_cli.warmup", "--job", name, "--out", tmp,
                                         "--data", str(sample)], cwd=REPO, stdout=subprocess.PIPE,
                                        stderr=subprocess.DEVNULL, text=True) for name in ("fusion", "planning")}
        try:
            for name, p in procs.items():
                try:
                    said, _ = p.communicate(timeout=timeout_s)
                except subprocess.TimeoutExpired:
                    p.kill()
                    said = f"did not end within {timeout_s:.0f} s"
                if p.returncode != 0:
                    failed.append(f"{name}: {said.strip()}")
        finally:  # interrupted: no job goes on compiling into a folder that is gone
            for p in procs.values():
                if p.poll() is None:
                    p.kill()
                    p.wait()
    return failed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(SAMPLE), help="folder holding recording.mcap and ground_truth/")
    ap.add_argument("--job", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    sample = Path(a.data)
    if a.job:  # one job, in a subprocess of warm()
        failed = []
        if a.job == "planning":  # first: the fusion job compiles the integration kernels both jobs call meanwhile
            try:
                api_kernels()
            except Exception as exc:  # noqa: BLE001 - reported, the warm-up goes on
                failed.append(f"library kernels: {exc}")
        failed += run_job(jobs(sample / "recording.mcap", sample / "ground_truth", Path(a.out))[a.job])
        if a.job == "fusion":
            try:
                reader_kernels()
            except Exception as exc:  # noqa: BLE001 - reported, the warm-up goes on
                failed.append(f"reader kernels: {exc}")
        print("; ".join(failed))
        return 1 if failed else 0
    if not (sample / "recording.mcap").exists():
        print(f"no {sample / 'recording.mcap'} to compile the kernels on: the first runs compile them")
        return 0
    if cache_is_warm():
        print("kinfu's numba kernels are compiled already")
        return 0
    print("compiling kinfu's numba kernels once (a minute or two; every later run loads them)", flush=True)
    t0 = time.perf_counter()
    failed = warm(sample, check_cache=False)
    for f in failed:
        print(f"warmup: {f}", file=sys.stderr)
    print(f"kernels compiled in {time.perf_counter() - t0:.0f} s" + (" (some stages failed)" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:  # the jobs share the terminal's process group: they stop too
        print("warmup: interrupted (the kernels compile in the first runs instead)", file=sys.stderr)
        sys.exit(130)
