"""What `kinfu segment` says when the support plane is missing or took every point (segmentation/pipeline.py)."""

from __future__ import annotations

import numpy as np

from kinfu_cli.segmentation.pipeline import support_plane_warnings
from kinfu_cli.segmentation.segments import Segmentation


def _seg(labels, plane=(0.0, 0.0, -1.0, 0.7), up=(0.0, 0.0, -1.0)) -> Segmentation:
    n = len(labels)
    return Segmentation(points=np.zeros((n, 3)), normals=np.zeros((n, 3)), labels=np.asarray(labels),
                        plane=None if plane is None else np.asarray(plane), supervoxels=-np.ones(n, int),
                        n_supervoxels=0, stats={"support_plane_search": {"up": list(up)}})


def test_a_support_plane_holding_every_point_is_said_with_the_up_it_faced():
    # a volume whose stored up was flipped: 0 objects, all 4735 points on the "support", and not a word
    (w,) = support_plane_warnings(_seg([0] * 50), "volume")
    assert "no objects" in w and "all 50 surface points" in w and "[0.0, 0.0, -1.0] (the volume's)" in w
    assert support_plane_warnings(_seg([0] * 40 + [1] * 10), "volume") == []  # objects found: nothing to say
    assert support_plane_warnings(_seg([], plane=None), "volume") == []
