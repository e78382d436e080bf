"""Tracking benchmark: projective ICP (fusion.icp, numba) vs open3d's ICP, the same tracker otherwise.

Run:  .venv/bin/python benchmarks/bench_tracking.py [--frames 60] [--repeat 3] [--methods projective,open3d]
Tracks the 7-Scenes kitchen frames 0..N-1 (640x480, depth as `kinfu fuse` filters it: range, fill-gaps 2) with
each method, frame-to-model from the first frame's recorded pose (constant-velocity prediction, 30 Hz), the
model a 5.9 mm TSDF (kinfu fuse's auto size for these frames) that each method builds from its own poses. The
methods run side by side, frame by frame, so that load from other processes hits both alike. Timed per method:
the tracker's calls (including its model ray casts and loss checks: "tracking fps") and tracking plus the
integration of the frame ("track+fuse fps", what `kinfu fuse --pose icp` does per frame, less reading the
recording). Prints per method: fps (mean over the runs, and the best of --repeat runs), CPU ms per frame
(all threads; on a loaded machine the honest measure: a frame needing C ms of CPU runs at >= 1000 / C fps on an
idle one even with no parallelism at all), ATE RMS / max (cm) against the recorded poses, frames lost, the speed
ratio (wall, and CPU time: less sensitive to other processes' load), and for the projective tracker the wall
time per phase (FrameToModelTracker.timing). A method name may carry tracker options as
`name:key=value+key=value` (e.g. `projective:band_start=0`, the session-5 cast) to compare settings in one process.
Not a test: the numbers go into the tracking report.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from kinfu_cli.fusion.filters import fill_gaps, range_filter  # noqa: E402
from kinfu_cli.fusion.placement import default_origin  # noqa: E402
from kinfu_cli.fusion.tracking import FrameToModelTracker, predict_pose  # noqa: E402
from kinfu_cli.fusion.volume import TernaryVolume  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _seven_scenes import SEVEN, seven_scenes_frames  # noqa: E402

DT = 1 / 30


def kitchen(n: int):
    """Frames 0..n-1 as (depth filtered as `kinfu fuse` does: range, fill-gaps 2; K; recorded pose; colour)."""
    return [(fill_gaps(range_filter(d, 0.3, 4.0), 2)[0], K, T, c) for d, c, K, T in seven_scenes_frames(n)]


class Run:
    """One method tracking the sequence: its own volume, poses and timings."""

    def __init__(self, method: str, frames):
        d0, K, T0, c0 = frames[0]
        origin = default_origin([(d0, K, T0)], 3.5)
        self.vol = TernaryVolume(size=3.5, voxel_size=3.0 / 512, origin=origin, truncation=0.03, color=False)
        self.vol.integrate(d0, K, T0)
        name, _, opts = method.partition(":")
        kw = {k: _value(v) for k, v in (o.split("=") for o in opts.split("+") if o)}
        self.tracker = FrameToModelTracker(icp=name, **kw)
        self.tracker.keep_reference(self.vol, d0, K, T0, c0)
        self.est = [T0]
        self.seconds = 0.0  # tracking, wall
        self.cpu = 0.0  # tracking, CPU (all threads)
        self.fused = 0.0  # tracking + integration, wall
        self.fused_cpu = 0.0  # tracking + integration, CPU (all threads)
        self.lost = 0
        self.conditions = []

    def step(self, d, K, color=None):
        prev2 = self.est[-2] if len(self.est) > 1 else None
        pred = predict_pose(self.est[-1], prev2, DT, DT)
        t0, c0 = time.perf_counter(), time.process_time()
        r = self.tracker.track(self.vol, d, K, [pred, self.est[-1]], T_ref=self.est[-1], dt_s=DT, color=color)
        self.seconds += time.perf_counter() - t0
        self.cpu += time.process_time() - c0
        self.conditions.append(r.condition)
        if r.lost:
            self.lost += 1
            self.est.append(self.est[-1])
        else:
            self.est.append(r.T_world_camera)
            self.vol.integrate(d, K, r.T_world_camera)
            self.tracker.keep_reference(self.vol, d, K, r.T_world_camera, color)
        self.fused += time.perf_counter() - t0
        self.fused_cpu += time.process_time() - c0


def _value(text: str):
    """A tracker option from the command line: a number, a tuple of numbers (a/b/c), or the text."""
    try:
        return tuple(float(x) if "." in x or "e" in x else int(x) for x in text.split("/")) if "/" in text \
            else (float(text) if "." in text or "e" in text else int(text))
    except ValueError:
        return text


def errors(est, frames):
    return np.array([np.linalg.norm(e[:3, 3] - f[2][:3, 3]) for e, f in zip(est, frames)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=3, help="runs of the whole sequence (best-of fps)")
    ap.add_argument("--methods", default="projective,open3d",
                    help="comma-separated; the last is the reference of the speed ratios")
    args = ap.parse_args()
    if not SEVEN.exists():
        sys.exit(f"no 7-Scenes frames at {SEVEN}")
    frames = kitchen(args.frames)
    methods = args.methods.split(",")
    # warm-up: numba compiles (cached after the first run)
    warm = Run("projective", frames[:2])
    warm.step(frames[1][0], frames[1][1])
    fps = {m: [] for m in methods}
    fused = {m: [] for m in methods}
    cpu = {m: [] for m in methods}
    fused_cpu = {m: [] for m in methods}
    phases = {m: {} for m in methods}
    last = {}
    for rep in range(args.repeat):
        runs = {m: Run(m, frames) for m in methods}
        for d, K, _, c in frames[1:]:
            for m in methods:
                runs[m].step(d, K, c)
        n = len(frames) - 1
        for m, r in runs.items():
            fps[m].append(n / r.seconds)
            fused[m].append(n / r.fused)
            cpu[m].append(r.cpu / n)
            fused_cpu[m].append(r.fused_cpu / n)
            for k, v in r.tracker.timing.items():
                phases[m].setdefault(k, []).append(v / n)
        last = runs
        print(f"run {rep + 1}: " + ", ".join(f"{m} {fps[m][-1]:.2f} fps" for m in methods), flush=True)
    print(f"\n7-Scenes kitchen frames 0-{len(frames) - 1} (640x480), tracked from frame 0's pose, {args.repeat} runs; "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    print("| method | tracking fps (mean) | tracking fps (best) | track+fuse fps (mean) | tracking CPU ms / frame | "
          "track+fuse CPU ms / frame | ATE RMS cm | ATE max cm | lost | median condition |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for m in methods:
        e = errors(last[m].est, frames)
        c = np.asarray(last[m].conditions, dtype=float)
        cond = np.nanmedian(c) if np.isfinite(c).any() else float("nan")
        print(f"| {m} | {np.mean(fps[m]):.2f} | {max(fps[m]):.2f} | {np.mean(fused[m]):.2f} | "
              f"{1000 * np.mean(cpu[m]):.1f} | {1000 * np.mean(fused_cpu[m]):.1f} | "
              f"{100 * np.sqrt(np.mean(e ** 2)):.2f} | {100 * e.max():.2f} | "
              f"{last[m].lost} | {cond:.3g} |")
    for m in methods:
        if phases[m]:
            total = sum(np.mean(v) for v in phases[m].values())
            print(f"\n{m}: wall ms per frame by phase (mean of runs; the rest of the tracker's time is Python glue)")
            print("| phase | ms | share |")
            print("|---|---|---|")
            for k, v in phases[m].items():
                print(f"| {k} | {1000 * np.mean(v):.1f} | {100 * np.mean(v) / total:.0f} % |")
            print(f"| all phases | {1000 * total:.1f} | of {1000 / np.mean(fps[m]):.1f} ms tracking |")
    ref = methods[-1]
    for m in methods[:-1]:
        ratio = [a / b for a, b in zip(fps[m], fps[ref])]
        print(f"\nspeed ratio {m} / {ref}: {np.mean(ratio):.1f}x (per run: " + ", ".join(f"{x:.1f}" for x in ratio)
              + ")")
        cratio = [b / a for a, b in zip(cpu[m], cpu[ref])]
        print(f"CPU-time ratio {ref} / {m} (CPU ms per tracked frame, all threads): {np.mean(cratio):.1f}x (per run: "
              + ", ".join(f"{x:.1f}" for x in cratio) + ")")


if __name__ == "__main__":
    main()
