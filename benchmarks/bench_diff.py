"""`kinfu diff` cleaning and grouping vs the dense scipy reference in the same process.

Ours (change/regions.py): the free-space erosion read only at the changed voxels, and 26-connected components
as a graph over those voxels (k-d tree + scipy.sparse.csgraph). Reference: scipy.ndimage.binary_erosion of the
other volume's whole free space (3x3x3, `margin` iterations) and scipy.ndimage.label (3x3x3) of the dense mask.
The grids: a room-sized tabletop (default 480 x 400 x 240 voxels, 46 M) with a moved object, a one-voxel pose
error and sensor speckles spread over it. Prints the median time of each over the repeats, the speed-up and
whether both give the same regions.
Usage: python benchmarks/bench_diff.py [--shape 480,400,240 --repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import ndimage

from kinfu_cli.change.regions import components, empty_all_around
from kinfu_cli.core.grid import EMPTY, OCCUPIED


def scene(shape, obj, shift, rng) -> np.ndarray:
    lab = np.zeros(shape, dtype=np.int8)
    table = shape[2] // 4
    lab[:, :, table + 3:] = EMPTY
    lab[:, :, table:table + 3] = OCCUPIED
    x, y = obj
    lab[x:x + 10, y:y + 10, table + 3:table + 13] = OCCUPIED
    lab[x + 2:x + 8, y + 2:y + 8, table + 5:table + 11] = 0
    lab = np.roll(lab, shift, axis=0)
    speckle = rng.random(shape) < 2e-5
    lab[speckle] = OCCUPIED
    return lab


def ours(before, after, margin):
    out = []
    for mask, other in (((before == OCCUPIED) & (after == EMPTY), after), ((before == EMPTY) & (after == OCCUPIED), before)):
        idx = np.argwhere(mask)
        out += [len(c) for c in components(idx[empty_all_around(other, idx, margin)])]
    return sorted(out)


def reference(before, after, margin):
    out = []
    cube = np.ones((3, 3, 3), dtype=bool)
    for mask, other in (((before == OCCUPIED) & (after == EMPTY), after), ((before == EMPTY) & (after == OCCUPIED), before)):
        kept = mask & ndimage.binary_erosion(other == EMPTY, structure=cube, iterations=margin, border_value=0)
        lab, n = ndimage.label(kept, structure=cube)
        out += np.bincount(lab.ravel(), minlength=n + 1)[1:].tolist()
    return sorted(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--shape", default="480,400,240")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--margin", type=int, default=1)
    a = ap.parse_args()
    shape = tuple(int(v) for v in a.shape.split(","))
    rng = np.random.default_rng(0)
    before = scene(shape, (50, 60), 0, rng)
    after = scene(shape, (300, 250), 1, rng)
    t_ours, t_ref = [], []
    for _ in range(a.repeat):
        t = time.perf_counter()
        mine = ours(before, after, a.margin)
        t_ours.append(time.perf_counter() - t)
        t = time.perf_counter()
        ref = reference(before, after, a.margin)
        t_ref.append(time.perf_counter() - t)
    mo, mr = float(np.median(t_ours)), float(np.median(t_ref))
    print(f"diff cleaning + regions, {np.prod(shape) / 1e6:.0f} M voxels, margin {a.margin}: ours {mo:.2f} s, "
          f"dense scipy {mr:.2f} s, speed-up x{mr / mo:.1f}; same regions: {mine == ref} "
          f"({len(mine)} regions, largest {mine[-1] if mine else 0} voxels)")


if __name__ == "__main__":
    main()
