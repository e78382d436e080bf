"""Tracking benchmark: projective ICP (fusion.icp, numba) vs open3d's ICP, the same tracker otherwise.

Run:  .venv/bin/python benchmarks/bench_tracking.py [--frames 60] [--repeat 3] [--methods projective,open3d]
Tracks the 7-Scenes kitchen frames 0..N-1 (640x480, depth as `kinfu fuse` filters it: range, fill-gaps 2) with
each method, frame-to-model from the first frame's recorded pose (constant-velocity prediction, 30 Hz), the
model a 5.9 mm TSDF (kinfu fuse's auto size for these frames) that each method builds from its own poses. The
methods run side by side, frame by frame, so that load from other processes hits both alike; only the
tracker's calls are timed (including its model ray casts and loss checks, not the integration). Prints per
method: fps (mean over the run, and the best of --repeat runs), ATE RMS / max (cm) against the recorded poses,
frames lost, and the speed ratio. Not a test: the numbers go into the tracking report.
"""

from __future__ import annotations

import argparse
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
    """Frames 0..n-1 as (depth filtered as `kinfu fuse` does: range, fill-gaps 2; K; recorded pose)."""
    return [(fill_gaps(range_filter(d, 0.3, 4.0), 2)[0], K, T) for d, _, K, T in seven_scenes_frames(n, color=False)]


class Run:
    """One method tracking the sequence: its own volume, poses and timings."""

    def __init__(self, method: str, frames):
        d0, K, T0 = frames[0]
        origin = default_origin([(d0, K, T0)], 3.5)
        self.vol = TernaryVolume(size=3.5, voxel_size=3.0 / 512, origin=origin, truncation=0.03, color=False)
        self.vol.integrate(d0, K, T0)
        self.tracker = FrameToModelTracker(icp=method)
        self.est = [T0]
        self.seconds = 0.0
        self.lost = 0
        self.conditions = []

    def step(self, d, K):
        prev2 = self.est[-2] if len(self.est) > 1 else None
        pred = predict_pose(self.est[-1], prev2, DT, DT)
        t0 = time.perf_counter()
        r = self.tracker.track(self.vol, d, K, [pred, self.est[-1]], T_ref=self.est[-1], dt_s=DT)
        self.seconds += time.perf_counter() - t0
        self.conditions.append(r.condition)
        if r.lost:
            self.lost += 1
            self.est.append(self.est[-1])
            return
        self.est.append(r.T_world_camera)
        self.vol.integrate(d, K, r.T_world_camera)


def errors(est, frames):
    return np.array([np.linalg.norm(e[:3, 3] - f[2][:3, 3]) for e, f in zip(est, frames)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=3, help="runs of the whole sequence (best-of fps)")
    ap.add_argument("--methods", default="projective,open3d")
    args = ap.parse_args()
    if not SEVEN.exists():
        sys.exit(f"no 7-Scenes frames at {SEVEN}")
    frames = kitchen(args.frames)
    methods = args.methods.split(",")
    # warm-up: numba compiles (cached after the first run)
    warm = Run("projective", frames[:2])
    warm.step(frames[1][0], frames[1][1])
    fps = {m: [] for m in methods}
    last = {}
    for rep in range(args.repeat):
        runs = {m: Run(m, frames) for m in methods}
        for d, K, _ in frames[1:]:
            for m in methods:
                runs[m].step(d, K)
        for m, r in runs.items():
            fps[m].append((len(frames) - 1) / r.seconds)
        last = runs
        print(f"run {rep + 1}: " + ", ".join(f"{m} {fps[m][-1]:.2f} fps" for m in methods), flush=True)
    print(f"\n7-Scenes kitchen frames 0-{len(frames) - 1} (640x480), tracked from frame 0's pose, best of "
          f"{args.repeat}")
    print("| method | fps (mean of runs) | fps (best) | ATE RMS cm | ATE max cm | lost | median condition |")
    print("|---|---|---|---|---|---|---|")
    for m in methods:
        e = errors(last[m].est, frames)
        c = np.asarray(last[m].conditions, dtype=float)
        cond = np.nanmedian(c) if np.isfinite(c).any() else float("nan")
        print(f"| {m} | {np.mean(fps[m]):.2f} | {max(fps[m]):.2f} | {100 * np.sqrt(np.mean(e ** 2)):.2f} | "
              f"{100 * e.max():.2f} | {last[m].lost} | {cond:.3g} |")
    if len(methods) == 2:
        ratio = [a / b for a, b in zip(fps[methods[0]], fps[methods[1]])]
        print(f"\nspeed ratio {methods[0]} / {methods[1]}: {np.mean(ratio):.1f}x (per run: "
              + ", ".join(f"{x:.1f}" for x in ratio) + ")")


if __name__ == "__main__":
    main()
