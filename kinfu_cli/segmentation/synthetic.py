"""Analytic tabletop scenes (signed distance of boxes, cylinders, spheres on a table) with object labels.

For segmentation tests and benchmarks that need a TSDF with a known answer, independent of the
simulator and of fusion: `tabletop_primitives(seed)` places objects (some stacked or touching) on a
table top at z = 0.7 m; `primitives_tsdf(...)` samples the truncated signed distance on a grid,
marking as known the free space and the truncation band behind surfaces (the interior and everything
below the table top stays unknown, as after a scan from above).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TABLE_TOP_Z = 0.7


@dataclass
class Primitive:
    """kind in {"box", "cylinder", "sphere"}; center (3,); half-extents (3,) (cylinder: r, r, h/2; sphere: r);
    yaw (rad, boxes); label: 0 = table, 1.. = objects."""

    kind: str
    center: np.ndarray
    half: np.ndarray
    yaw: float = 0.0
    label: int = 0

    def sdf(self, p: np.ndarray) -> np.ndarray:
        q = np.asarray(p, dtype=np.float64) - self.center
        if self.kind == "sphere":
            return np.linalg.norm(q, axis=-1) - self.half[0]
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        x = c * q[..., 0] + s * q[..., 1]
        y = -s * q[..., 0] + c * q[..., 1]
        if self.kind == "box":
            d = np.stack([np.abs(x), np.abs(y), np.abs(q[..., 2])], axis=-1) - self.half
        elif self.kind == "cylinder":
            d = np.stack([np.hypot(x, y) - self.half[0], np.abs(q[..., 2]) - self.half[2]], axis=-1)
        else:
            raise ValueError(self.kind)
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
        return outside + np.minimum(d.max(axis=-1), 0.0)


def tabletop_primitives(seed: int = 0, n_objects: int = 5, stacked: bool = True) -> list[Primitive]:
    """A 1.2 x 0.8 m table (top at z = 0.7) with `n_objects` objects 6-16 cm in size, at least 4 cm apart,
    plus (with `stacked`) one box standing on another (a concave junction segmentation must cut)."""
    rng = np.random.default_rng(seed)
    prims = [Primitive("box", np.array([0.0, 0.0, TABLE_TOP_Z - 0.02]), np.array([0.6, 0.4, 0.02]), 0.0, 0)]
    placed: list[tuple[np.ndarray, float]] = []
    label = 1
    tries = 0
    while label <= n_objects and tries < 500:
        tries += 1
        kind = ("box", "cylinder", "sphere")[label % 3]
        if kind == "box":
            half = rng.uniform([0.03, 0.03, 0.03], [0.07, 0.06, 0.08])
        elif kind == "cylinder":
            r = rng.uniform(0.03, 0.05)
            half = np.array([r, r, rng.uniform(0.04, 0.08)])
        else:
            r = rng.uniform(0.035, 0.06)
            half = np.array([r, r, r])
        foot = float(np.hypot(half[0], half[1])) if kind == "box" else float(half[0])
        xy = rng.uniform([-0.45, -0.28], [0.45, 0.28])
        if any(np.linalg.norm(xy - c) < foot + f + 0.04 for c, f in placed):
            continue
        zc = TABLE_TOP_Z + half[2]
        prims.append(Primitive(kind, np.array([xy[0], xy[1], zc]), half, float(rng.uniform(0, np.pi)), label))
        placed.append((xy, foot))
        label += 1
    if stacked:
        base = next((p for p in prims[1:] if p.kind == "box"), None)
        if base is not None:
            top_half = np.array([0.6, 0.6, 0.8]) * base.half
            c = base.center + np.array([0, 0, base.half[2] + top_half[2]])
            prims.append(Primitive("box", c, top_half, base.yaw + 0.5, label))
    return prims


def scene_sdf(prims: list[Primitive], points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance of the union and the label of the nearest primitive, for points (..., 3)."""
    d = np.stack([p.sdf(points) for p in prims], axis=-1)
    idx = np.argmin(d, axis=-1)
    labels = np.array([p.label for p in prims])[idx]
    return np.take_along_axis(d, idx[..., None], axis=-1)[..., 0], labels


def primitives_tsdf(prims: list[Primitive], origin, voxel_size: float, shape, truncation: float = 0.03,
                    box_min=(-0.7, -0.5, 0.6), box_max=(0.7, 0.5, 1.05), weight: float = 10.0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(tsdf float32, weight float32) on a grid [x, y, z]; only the box [box_min, box_max] is observed.

    Known: free space (sdf > 0) above the table top and the truncation band behind surfaces; unknown:
    deeper interiors, below the table top, and outside the box.
    """
    origin = np.asarray(origin, dtype=np.float64)
    shape = tuple(int(s) for s in shape)
    tsdf = np.ones(shape, dtype=np.float32)
    w = np.zeros(shape, dtype=np.float32)
    lo = np.clip(np.floor((np.asarray(box_min) - origin) / voxel_size).astype(int), 0, shape)
    hi = np.clip(np.ceil((np.asarray(box_max) - origin) / voxel_size).astype(int), 0, shape)
    if np.any(hi <= lo):
        return tsdf, w
    for i0 in range(lo[0], hi[0], 64):  # slabs keep the temporaries small on big grids
        i1 = min(i0 + 64, hi[0])
        ii, jj, kk = np.meshgrid(np.arange(i0, i1), np.arange(lo[1], hi[1]), np.arange(lo[2], hi[2]),
                                 indexing="ij")
        pts = origin + (np.stack([ii, jj, kk], axis=-1) + 0.5) * voxel_size
        d, _ = scene_sdf(prims, pts)
        known = (d > -truncation) & ((d < 0) | (pts[..., 2] > TABLE_TOP_Z - truncation))
        tsdf[i0:i1, lo[1]:hi[1], lo[2]:hi[2]] = np.clip(d / truncation, -1, 1)
        w[i0:i1, lo[1]:hi[1], lo[2]:hi[2]] = np.where(known, weight, 0)
    return tsdf, w


def label_points(prims: list[Primitive], points: np.ndarray, max_distance: float = 0.01) -> np.ndarray:
    """Ground-truth label of surface points (nearest primitive), -1 when farther than `max_distance`."""
    dist = np.stack([np.abs(p.sdf(points)) for p in prims], axis=-1)
    idx = np.argmin(dist, axis=-1)
    lab = np.array([p.label for p in prims])[idx]
    return np.where(dist.min(axis=-1) <= max_distance, lab, -1)
