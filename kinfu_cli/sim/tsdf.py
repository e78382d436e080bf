"""The ideal TSDF volume of a scene: what fusion would build from perfect depth, with a known answer.

`scene_tsdf` samples the scene's exact signed distance (`Scene.sdf`) at the voxel centres of a grid, truncated,
and marks as known (weight > 0) what a scan from above would have observed inside a box: the free space above
the table top and the truncation band behind every surface. Interiors deeper than the band, everything below
the table top and everything outside the box stay unknown. For segmentation and view-planning tests that must
not depend on fusion or on sensor noise.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.sim.scene import Scene


def scene_tsdf(scene: Scene, origin, voxel_size: float, shape, truncation: float = 0.03, box_min=None,
               box_max=None, weight: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """(tsdf float32, weight float32) on a grid indexed [x, y, z] with voxel (0, 0, 0) at `origin`; only the
    box [box_min, box_max] is observed (default: the table grown by 10 cm, from 10 cm below its top to 35 cm
    above)."""
    table = scene.table
    if box_min is None:
        box_min = (table.center[0] - table.size[0] / 2 - 0.1, table.center[1] - table.size[1] / 2 - 0.1,
                   table.top_z - 0.1)
    if box_max is None:
        box_max = (table.center[0] + table.size[0] / 2 + 0.1, table.center[1] + table.size[1] / 2 + 0.1,
                   table.top_z + 0.35)
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
        d = scene.sdf(pts)
        known = (d > -truncation) & ((d < 0) | (pts[..., 2] > table.top_z - truncation))
        tsdf[i0:i1, lo[1]:hi[1], lo[2]:hi[2]] = np.clip(d / truncation, -1, 1)
        w[i0:i1, lo[1]:hi[1], lo[2]:hi[2]] = np.where(known, weight, 0)
    return tsdf, w
