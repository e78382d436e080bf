"""Grasp solver time per single-superquadric object (thesis Table 7.2 sizes as box / cylinder / ellipsoid, 2 yaws,
no / top / side cone; `kinfu eval grasp`'s generated set), for the gradient schemes of `grasp/solve.py`, run in
the same process, alternating, `repeats` times: CPU s in all, median, p95 and max per object, the largest SLSQP
iteration count, and the ratio of each scheme's total to the default's. "forward" everywhere is the gradient
of the solver before session 6 (its top-cone runs stalled at the optimum until their iteration limit; the
refinement legs of session 6 now cut those runs short, so this is faster than the old solver).

    PYTHONPATH=$PWD python benchmarks/bench_grasp.py [repeats]
"""

import sys
import time

import numpy as np

from kinfu_cli.grasp import solve
from kinfu_cli.grasp.constraints import default_workspaces, preset_cone
from kinfu_cli.grasp.evaluate import PLANE, generated_objects
from kinfu_cli.grasp.plan import GraspOptions, grasp_object

# (screening gradient, refinement gradient): the default first
SCHEMES = {"default (forward / central)": ("forward", "central"), "central / central": ("central", "central"),
           "forward / forward": ("forward", "forward"), "analytic / analytic": ("analytic", "analytic")}


def run_set(objects) -> tuple[np.ndarray, int]:
    """CPU s per object over every object x cone condition, and the largest iteration count."""
    times, iters = [], 0
    for cond in ("none", "top", "side"):
        opts = GraspOptions(hand="right", cones=[] if cond == "none" else [preset_cone(cond, PLANE[:3])])
        for _, parts in objects:
            ws = default_workspaces(np.array([q.center for q in parts]), PLANE[:3])
            c0 = time.process_time()
            o = grasp_object(0, parts, PLANE, ws, opts)
            times.append(time.process_time() - c0)
            iters = max(iters, max(c[2].iterations for c in o.candidates))
    return np.array(times), iters


def main(repeats: int = 3) -> None:
    objects = [o for o in generated_objects(2, 0) if len(o[1]) == 1]
    run_set(objects)  # warm-up
    totals: dict[str, list[float]] = {k: [] for k in SCHEMES}
    for rep in range(repeats):
        for name, (screen, refine) in SCHEMES.items():
            solve.SCREEN_GRADIENT, solve.GRADIENT = screen, refine
            t, it = run_set(objects)
            totals[name].append(t.sum())
            print(f"{rep}  {name:28} total {t.sum():6.3f}  median {np.median(t):.4f}  p95 {np.percentile(t, 95):.4f}"
                  f"  max {t.max():.4f}  max iterations {it}", flush=True)
    solve.SCREEN_GRADIENT, solve.GRADIENT = SCHEMES["default (forward / central)"]
    ref = np.array(totals["default (forward / central)"])
    print(f"CPU total / default's, same process, {len(objects) * 3} objects x {repeats} repeats:")
    for name, v in totals.items():
        r = np.array(v) / ref
        print(f"  {name:28} {np.median(r):.2f} (min {r.min():.2f}, max {r.max():.2f})")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
