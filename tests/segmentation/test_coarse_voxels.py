"""`kinfu segment` on a volume fused with voxels too coarse for the segmentation says so.

Before: the synthetic tabletop fused with `--voxel-size 0.02` (or 0.05) gave "0 segments + support plane" and no
warning: its surface points lie a voxel apart, farther than the 18 mm adjacency radius, so nothing could join.
"""

import numpy as np

from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume


def _tabletop(vs: float) -> TernaryGrid:
    """A 0.8 m table top with a 12 cm box on it, as occupied voxels of edge vs (empty above, unknown inside)."""
    n = int(round(0.8 / vs))
    lab = np.full((n, n, n), EMPTY, np.int8)
    t = n // 4
    lab[:, :, :t] = UNKNOWN
    lab[:, :, t] = OCCUPIED
    b = int(round(0.12 / vs))
    lo = n // 2 - b // 2
    lab[lo:lo + b, lo:lo + b, t + 1:t + 1 + b] = OCCUPIED
    lab[lo + 1:lo + b - 1, lo + 1:lo + b - 1, t + 1:t + b] = UNKNOWN
    return TernaryGrid(lab, np.zeros(3), vs)


def test_voxels_coarser_than_the_adjacency_radius_are_a_warning():
    res = analyse_volume(_tabletop(0.02), SegmentOptions(superquadrics=False))
    (w,) = [w for w in res.warnings if "voxels" in w]
    assert "20.0 mm" in w and "no object can form a segment" in w and "at most 9 mm" in w


def test_fine_voxels_segment_the_box_without_that_warning():
    res = analyse_volume(_tabletop(0.008), SegmentOptions(superquadrics=False))
    assert not [w for w in res.warnings if "adjacency radius" in w]
    assert set(np.unique(res.segmentation.labels).tolist()) - {-1, 0} == {1}  # the box, one segment
