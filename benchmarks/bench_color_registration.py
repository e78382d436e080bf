"""Colour from a camera beside the depth camera (io.color_registration.register_color, numba) against the numpy
form it replaced (np.minimum.at z-buffer), in the same process, on a 640x480 frame of a generated tabletop seen by
a depth camera and a colour camera 1.5 cm apart: milliseconds of each (median of 10) and whether the two agree.

Run: .venv/bin/python benchmarks/bench_color_registration.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from kinfu_cli.io.color_registration import OCCLUSION_MARGIN, ColorRegistration, register_color  # noqa: E402
from kinfu_cli.sim.paths import orbit_poses  # noqa: E402
from kinfu_cli.sim.scene import primitive_tabletop_scene  # noqa: E402
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics  # noqa: E402
from kinfu_cli.io.undistort import Undistorter  # noqa: E402


def reference(reg, depth, K_depth, color):
    """The numpy form: back-project, transform, project, z-buffer with np.minimum.at, gather."""
    h, w = depth.shape
    ch, cw = color.shape[:2]
    v, u = np.nonzero(depth > 0)
    z = depth[v, u].astype(np.float64)
    pts = np.stack([(u - K_depth[0, 2]) / K_depth[0, 0] * z, (v - K_depth[1, 2]) / K_depth[1, 1] * z, z], axis=1)
    pc = pts @ reg.T_color_depth[:3, :3].T + reg.T_color_depth[:3, 3]
    K = reg.K_color
    uc = np.floor(pc[:, 0] / pc[:, 2] * K[0, 0] + K[0, 2] + 0.5)
    vc = np.floor(pc[:, 1] / pc[:, 2] * K[1, 1] + K[1, 2] + 0.5)
    ok = (pc[:, 2] > 0) & (uc >= 0) & (uc < cw) & (vc >= 0) & (vc < ch)
    flat = (vc[ok] * cw + uc[ok]).astype(np.int64)
    nearest = np.full(cw * ch, np.inf)
    np.minimum.at(nearest, flat, pc[ok, 2])
    seen = pc[ok, 2] <= nearest[flat] + OCCLUSION_MARGIN
    out = np.zeros((h, w, 3), dtype=np.uint8)
    idx = np.flatnonzero(ok)[seen]
    out[v[idx], u[idx]] = color.reshape(-1, 3)[flat[seen]]
    return out


def main() -> None:
    K = kinect_v1_intrinsics(640, 480)
    T_dc = np.eye(4)
    T_dc[0, 3] = 0.015
    pose = orbit_poses(1, radius=0.85, height=1.3, target=(0.0, 0.0, 0.75))[0]
    scene = primitive_tabletop_scene(seed=2)
    depth, _ = DepthSensor(K, 640, 480, noise=True, seed=2).render(scene, pose)
    _, color = DepthSensor(K, 640, 480, noise=False).render(scene, pose @ T_dc)
    reg = ColorRegistration("project", "depth", "colour", "/info", Undistorter.pinhole(K), (640, 480),
                            np.linalg.inv(T_dc))
    ours = register_color(reg, depth, K, color, "bench")[0]  # compile / load the cache
    ref = reference(reg, depth, K, color)
    times = {}
    for name, f in (("numpy (reference)", reference), ("numba", lambda *a: register_color(*a, "bench"))):
        ts = []
        for _ in range(10):
            t = time.perf_counter()
            f(reg, depth, K, color)
            ts.append(time.perf_counter() - t)
        times[name] = 1000 * float(np.median(ts))
    same = float(np.mean(np.all(ours == ref, axis=2)))
    print(f"numpy reference {times['numpy (reference)']:.1f} ms, numba {times['numba']:.1f} ms "
          f"(ratio {times['numba'] / times['numpy (reference)']:.3f}); pixels equal: {100 * same:.3f} %")


if __name__ == "__main__":
    main()
