"""The ternary-grid surface (`surface_from_labels`) computed chunk by chunk is the whole-box computation it
replaced, to the last bit: the same points in the same order, the same normals (7-Scenes kitchen ternary.npz:
surface 11.7 s -> 0.7 s)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from kinfu_cli.segmentation.surface import _active_box, surface_from_labels


def _whole_box(labels: np.ndarray, origin, voxel_size: float, smoothing: float = 1.0):
    """The reference: the field smoothed over the whole box, np.gradient over all of it (session 24's code)."""
    box = _active_box(labels == 1, pad=3)
    lab = labels[box]
    occ, emp = lab == 1, lab == -1
    pad_e = np.pad(emp, 1)
    touch = np.zeros_like(occ)
    for ax in range(3):
        for sh in (-1, 1):
            touch |= np.roll(pad_e, sh, axis=ax)[1:-1, 1:-1, 1:-1]
    surf = occ & touch
    idx = np.argwhere(surf)
    field = gaussian_filter(np.where(occ, -1.0, np.where(emp, 1.0, 0.0)).astype(np.float32), smoothing)
    g = np.stack(np.gradient(field), axis=-1)[surf]
    pts = np.asarray(origin, dtype=np.float64) + (idx + np.array([s.start for s in box]) + 0.5) * voxel_size
    return pts, g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_chunked_surface_is_the_whole_box_one(seed):
    """Random grids (noise everywhere, or boxes touching the grid's faces, where np.gradient goes one-sided) and
    chunks from 5 voxels (the Gaussian's reach crosses several) to larger than the grid."""
    rng = np.random.default_rng(seed)
    shape = tuple(int(n) for n in rng.integers(20, 80, 3))
    if seed % 2:
        labels = np.full(shape, -1, np.int8)
        labels[3:15, 0:20, 5:9] = 1
        labels[0, :, :] = 1
        labels[-3:, -5:, -1] = 0
    else:
        labels = rng.choice(np.array([-1, 0, 1], np.int8), size=shape, p=[0.5, 0.2, 0.3])
    ref_pts, ref_nrm = _whole_box(labels, (0.1, -0.2, 0.3), 0.01)
    for chunk in (5, 17, 48, 200):
        cloud = surface_from_labels(labels, (0.1, -0.2, 0.3), 0.01, resolution=None, chunk=chunk)
        assert np.array_equal(cloud.points, ref_pts) and np.array_equal(cloud.normals, ref_nrm)
