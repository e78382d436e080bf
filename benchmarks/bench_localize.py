"""`kinfu localize` hot spots vs the library references, in the same process (ratios, repeated).

1. Euler angles -> rotation matrices for 10^4 poses: ours (numpy, written out) vs scipy Rotation.from_euler.
2. Point-to-mesh distance and closest points for 5x10^4 queries near the surface: the trilinear signed-distance
   field vs open3d RaycastingScene (the BVH it is sampled from); also the field's error against the BVH.
3. MUPF runs (robot mesh, L = 40, N = 700, numba kernels over the field): wall and CPU seconds per run, the
   issue's budget being <= 1 s per trial on 2 cores; the same trial with the default refinement and with
   `NO_REFINE` (the thesis' MAP particle), as a CPU ratio: what the candidates' polish costs.
Usage: python benchmarks/bench_localize.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.localization import shapes
from kinfu_cli.localization.mesh_model import euler_matrices
from kinfu_cli.localization.mupf import NO_REFINE, MupfParameters, localize_mupf
from kinfu_cli.localization.protocol import make_trial


def _best(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, min(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-mupf", action="store_true")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    ang = rng.uniform(-np.pi, np.pi, (10000, 3))
    ours, t_ours = _best(lambda: euler_matrices(ang), args.repeat)
    ref, t_ref = _best(lambda: Rotation.from_euler("ZYX", ang).as_matrix(), args.repeat)
    print(f"euler->matrix 1e4: numpy {t_ours * 1e3:.2f} ms, scipy {t_ref * 1e3:.2f} ms, x{t_ref / t_ours:.1f}, "
          f"max diff {np.abs(ours - ref).max():.1e}")
    model = shapes.robot()
    q = model.sample_surface(50000, rng) + rng.normal(0, 0.01, (50000, 3))
    bvh_d, t_bvh = _best(lambda: model.exact_distances(q), args.repeat)
    bvh_c, t_bvhc = _best(lambda: model.exact_closest_points(q), args.repeat)
    model.build_field()
    fld_d, t_fld = _best(lambda: model.distances(q), args.repeat)
    fld_c, t_fldc = _best(lambda: model.closest_points(q), args.repeat)
    err = np.abs(fld_d - bvh_d)
    cerr = np.linalg.norm(fld_c - bvh_c, axis=1)
    print(f"distance 5e4: field {t_fld * 1e3:.1f} ms, BVH {t_bvh * 1e3:.1f} ms, x{t_bvh / t_fld:.1f}; "
          f"|error| median {np.median(err) * 1e3:.3f} mm, p99 {np.percentile(err, 99) * 1e3:.2f} mm")
    print(f"closest point 5e4: field {t_fldc * 1e3:.1f} ms, BVH {t_bvhc * 1e3:.1f} ms, x{t_bvhc / t_fldc:.1f}; "
          f"error median {np.median(cerr) * 1e3:.3f} mm, p90 {np.percentile(cerr, 90) * 1e3:.2f} mm")
    if args.skip_mupf:
        return
    params = MupfParameters(window=24)
    bare = MupfParameters(window=24, **NO_REFINE)
    for k in range(args.repeat + 1):  # the first run compiles (or loads the numba cache)
        trial = make_trial(model, 40, 0.002, rng)
        wall, cpu = time.perf_counter(), time.process_time()
        localize_mupf(model, trial.points, params, seed=k)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        cpu_bare = time.process_time()
        localize_mupf(model, trial.points, bare, seed=k)
        cpu_bare = time.process_time() - cpu_bare
        if k:
            print(f"MUPF robot L=40 N=700: wall {wall:.2f} s, cpu {cpu:.2f} s; without refinement cpu {cpu_bare:.2f} s "
                  f"(refined / bare x{cpu / cpu_bare:.2f})")


if __name__ == "__main__":
    main()
