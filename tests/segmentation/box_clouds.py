"""Exact surface samples of axis-aligned boxes standing on a table, shared by the cut tests: a fused cloud's
spacing without its noise, so a test sees the rule it checks and nothing else."""

from __future__ import annotations

import numpy as np

from kinfu_cli.segmentation.segments import SegmentationParams, segment_cloud


def face_points(lo, hi, axis: int, side: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Grid points (spacing step) on one face of the box lo..hi with the outward normal along +-axis."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ax = [a for a in range(3) if a != axis]
    u = np.arange(lo[ax[0]] + step / 2, hi[ax[0]], step)
    v = np.arange(lo[ax[1]] + step / 2, hi[ax[1]], step)
    g = np.stack(np.meshgrid(u, v, indexing="ij"), -1).reshape(-1, 2)
    p = np.zeros((len(g), 3))
    p[:, ax[0]], p[:, ax[1]] = g[:, 0], g[:, 1]
    p[:, axis] = hi[axis] if side > 0 else lo[axis]
    n = np.zeros_like(p)
    n[:, axis] = side
    return p, n


def box_faces(lo, hi, step: float, skip=()) -> tuple[np.ndarray, np.ndarray]:
    """Grid points and outward normals on the faces of the box lo..hi; the bottom and the (axis, side) faces in
    skip are left out (hidden by the table or a touching box)."""
    faces = [face_points(lo, hi, axis, side, step) for axis in range(3) for side in (-1, 1)
             if not (axis == 2 and side < 0) and (axis, side) not in skip]
    return np.concatenate([f[0] for f in faces]), np.concatenate([f[1] for f in faces])


def object_segments(points: np.ndarray, normals: np.ndarray, **params):
    """(segmentation with z up, the object segment ids)."""
    seg = segment_cloud(points, normals, SegmentationParams(up=(0.0, 0.0, 1.0), **params))
    return seg, [int(s) for s in np.unique(seg.labels) if s > 0]
