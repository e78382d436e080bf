"""Per-voxel object labels of a generated scene: ground_truth/labels.npz of `kinfu synth`.

A voxel is occupied when its centre lies inside a part of the scene or within half a voxel of its surface; only
the occupied voxels at most `depth` voxels inside the surface are stored (the shell a fused TSDF marks occupied;
deeper voxels are never observed). Each takes the label of the part its centre is deepest in (0 = background:
table, floor, walls; 1.. objects, the `label` of changes.json). The grid's origin is a multiple of the voxel size,
so voxel (i, j, k) has its centre at origin + (index + 0.5) * voxel_size.

The file holds `points` (M, 3) voxel centres and `labels` (M,), so it is a labels file like labels.ply
(`io.labelled_cloud`), plus `index` (M, 3) int32, `origin` (3,) and `voxel_size` for voxel-level use.
Signed distances are evaluated only in coarse blocks the surface passes near, so a room costs its surface.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

# (points (P, 3)) -> [(label, signed distance (P,)), ...], negative inside a part
PartDistances = Callable[[np.ndarray], list[tuple[int, np.ndarray]]]
BLOCK = 8  # voxels per coarse block edge


def _centres(origin: np.ndarray, idx: np.ndarray, voxel_size: float) -> np.ndarray:
    return origin + (idx + 0.5) * voxel_size


def voxel_labels(distances: PartDistances, lo, hi, voxel_size: float, depth: int = 3
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(index (M, 3) int32, centres (M, 3), labels (M,) int32) of the occupied shell voxels in the box lo..hi
    (module docstring); origin = floor(lo / voxel_size) * voxel_size."""
    vs = float(voxel_size)
    origin = np.floor(np.asarray(lo, dtype=np.float64) / vs) * vs
    shape = np.ceil((np.asarray(hi, dtype=np.float64) - origin) / vs).astype(np.int64)
    nb = -(-shape // BLOCK)
    bidx = np.stack(np.meshgrid(*[np.arange(n) for n in nb], indexing="ij"), -1).reshape(-1, 3)
    bc = origin + (bidx + 0.5) * BLOCK * vs
    dist = np.min([np.abs(d) for _, d in distances(bc)], axis=0)
    near = bidx[dist <= (np.sqrt(3) / 2 * BLOCK + depth + 1) * vs]  # the surface may pass through the block
    local = np.stack(np.meshgrid(*[np.arange(BLOCK)] * 3, indexing="ij"), -1).reshape(-1, 3)
    out_idx, out_lab = [], []
    for chunk in np.array_split(near, max(1, len(near) // 2000)):  # ~1M voxels at a time
        idx = (chunk[:, None, :] * BLOCK + local[None]).reshape(-1, 3)
        idx = idx[np.all(idx < shape, axis=1)]
        parts = distances(_centres(origin, idx, vs))
        sd = np.stack([d for _, d in parts], -1)
        deepest = np.argmin(sd, axis=-1)
        smin = sd[np.arange(len(idx)), deepest]
        keep = (smin <= vs / 2) & (smin >= -depth * vs)
        out_idx.append(idx[keep].astype(np.int32))
        out_lab.append(np.asarray([label for label, _ in parts], dtype=np.int32)[deepest[keep]])
    idx = np.concatenate(out_idx) if out_idx else np.zeros((0, 3), np.int32)
    lab = np.concatenate(out_lab) if out_lab else np.zeros(0, np.int32)
    return idx, _centres(origin, idx, vs), lab


def write_voxel_labels(path: str | os.PathLike, distances: PartDistances, lo, hi, voxel_size: float,
                       depth: int = 3) -> Path:
    """Compute `voxel_labels` and write them as labels.npz (module docstring); callers write inside an
    `atomic_dir` (the ground-truth folder is replaced as a whole)."""
    vs = float(voxel_size)
    idx, pts, lab = voxel_labels(distances, lo, hi, vs, depth)
    origin = np.floor(np.asarray(lo, dtype=np.float64) / vs) * vs
    with open(path, "wb") as f:
        np.savez_compressed(f, points=pts, labels=lab, index=idx, origin=origin, voxel_size=np.float64(vs),
                            depth=np.int32(depth))
    return Path(path)
