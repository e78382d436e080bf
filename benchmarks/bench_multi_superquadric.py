"""Multi-superquadric split (Algs. 4-6) on generated composites of known parts: the number of superquadrics
per mu (m), against the true number of parts, over a few seeds; more parts than true = over-segmentation.

    PYTHONPATH=$PWD python benchmarks/bench_multi_superquadric.py [n_seeds]
"""

import sys
import time

import numpy as np

from kinfu_cli.segmentation import multi_superquadric as msq
from kinfu_cli.segmentation.shape_samples import COMPOSITES, composite_cloud, primitive_cloud

FIT: dict = {}
MUS = (0.01, 0.015, 0.02, 0.03, 0.04, 0.05, 0.06)


def main(n_seeds: int = 3) -> None:
    shapes = dict(COMPOSITES, box=1, cylinder=1)
    print("shape     parts  " + "  ".join(f"mu={m:<5}" for m in MUS) + "  tree s")
    for name, true_parts in shapes.items():
        counts, secs = [], []
        for seed in range(n_seeds):
            rng = np.random.default_rng(seed)
            pts = primitive_cloud(name, rng) if name in ("box", "cylinder") else composite_cloud(name, rng)[0]
            t = time.perf_counter()
            root = msq.build_superquadric_tree(pts, **FIT)
            secs.append(time.perf_counter() - t)
            row = []
            for mu in MUS:
                msq.select_splitting_planes(root, mu)
                row.append(len(msq.final_superquadrics(root, pts, mu, **FIT).parts))
            counts.append(row)
        c = np.array(counts)
        cells = ["/".join(str(v) for v in c[:, j]) for j in range(len(MUS))]
        print(f"{name:9} {true_parts:5}  " + "  ".join(f"{s:8}" for s in cells) + f"  {np.mean(secs):.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 3)
