"""Simulated Kinect render speed vs a bare open3d depth ray cast of the same view (same process).

Reference: open3d RaycastingScene.create_rays_pinhole + cast_rays (depth only, no noise, no colour).
Ours: DepthSensor.render (noise-free: depth + shaded colour; noisy: + lateral re-cast, projector shadow test,
axial noise, disparity quantisation, dropouts). Prints ms per frame and the ratio to the reference.
Usage: python benchmarks/bench_sim.py [--width 640 --height 480 --repeat 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import open3d as o3d

from kinfu_cli.sim.scenario import make_scenario
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics


def _time(fn, repeat: int) -> float:
    fn()  # warm-up (numba compile, BVH build)
    t = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t) / repeat


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    sc = make_scenario(0, width=32, height=24, frames=6)
    K = kinect_v1_intrinsics(a.width, a.height)
    T = sc.frames[2].T_world_camera
    target = sc.scene_before.raycasting_scene()
    rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
        o3d.core.Tensor(K), o3d.core.Tensor(np.linalg.inv(T)), a.width, a.height)

    ref = _time(lambda: target.scene.cast_rays(rays)["t_hit"].numpy(), a.repeat)
    clean = DepthSensor(K, a.width, a.height, noise=False)
    noisy = DepthSensor(K, a.width, a.height, noise=True)
    t_clean = _time(lambda: clean.render(target, T), a.repeat)
    t_noisy = _time(lambda: noisy.render(target, T), a.repeat)
    print(f"{a.width}x{a.height}: reference open3d depth cast {ref * 1e3:.1f} ms")
    print(f"  DepthSensor noise-free (depth + colour): {t_clean * 1e3:.1f} ms  ratio {t_clean / ref:.2f}x reference")
    print(f"  DepthSensor Kinect noise model:          {t_noisy * 1e3:.1f} ms  ratio {t_noisy / ref:.2f}x reference")


if __name__ == "__main__":
    main()
