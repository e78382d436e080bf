"""`kinfu eval fusion` hot spots vs reference implementations in the same process, on the sample ground truth.

1. Visibility of the true surface: ours renders one depth image per camera pose (open3d ray cast, W x H rays) and
   compares depths (z-buffer); the reference casts one ray from the camera to every candidate sample and pose.
   Prints ms, the speed-up and the share of samples on which both agree.
2. Point-to-mesh distance: open3d RaycastingScene.compute_distance (ours) vs a scipy cKDTree to a dense
   (2 mm) sampling of the true mesh (a common stand-in); prints ms, speed-up and the mean difference.
Usage: python benchmarks/bench_eval_fusion.py [--spacing 0.005 --frames 24]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from kinfu_cli.evaluation.reconstruction import mesh_scene, point_to_mesh_distance, visible_mask, visible_mask_exact
from kinfu_cli.sim.sampling import sample_surface
from kinfu_cli.sim.scenario import load_ground_truth

GT = Path(__file__).resolve().parents[1] / "sample_data" / "tabletop" / "ground_truth"


def _timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--spacing", type=float, default=0.005)
    ap.add_argument("--frames", type=int, default=24)
    a = ap.parse_args()
    gt = load_ground_truth(GT)
    m = gt.mesh("before")
    v, f = np.asarray(m.vertices), np.asarray(m.triangles)
    scene = mesh_scene(v, f)
    pts, nrm = sample_surface(v, f, spacing=a.spacing)
    keep = np.all(np.abs(pts[:, :2]) < 1.5, axis=1)
    pts, nrm = pts[keep], nrm[keep]
    poses = gt.poses[: a.frames]
    visible_mask(pts[:1000], nrm[:1000], scene, poses[:1], gt.K, gt.width, gt.height)  # warm-up
    ours, t_ours = _timed(lambda: visible_mask(pts, nrm, scene, poses, gt.K, gt.width, gt.height))
    ref, t_ref = _timed(lambda: visible_mask_exact(pts, nrm, scene, poses, gt.K, gt.width, gt.height))
    print(f"visibility, {len(pts)} samples x {len(poses)} poses: z-buffer {t_ours * 1e3:.0f} ms, exact rays "
          f"{t_ref * 1e3:.0f} ms, speed-up x{t_ref / t_ours:.1f}, agreement {np.mean(ours == ref) * 100:.2f} %")

    q = pts[ours][:100_000] + np.random.default_rng(0).normal(0, 0.005, (min(100_000, int(ours.sum())), 3))
    d_ours, t_ours = _timed(lambda: point_to_mesh_distance(q, v, f, scene))
    from scipy.spatial import cKDTree

    dense, _ = sample_surface(v, f, spacing=0.002)
    dense = dense[np.all(np.abs(dense[:, :2]) < 1.6, axis=1)]
    d_ref, t_ref = _timed(lambda: cKDTree(dense).query(q, workers=-1)[0])
    print(f"distance, {len(q)} points: RaycastingScene {t_ours * 1e3:.0f} ms, cKDTree on {len(dense)} dense samples "
          f"(build + query) {t_ref * 1e3:.0f} ms, speed-up x{t_ref / t_ours:.1f}, mean |diff| "
          f"{np.mean(np.abs(d_ours - d_ref)) * 1e3:.2f} mm")


if __name__ == "__main__":
    main()
