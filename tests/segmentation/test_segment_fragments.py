"""Fragments (segments.py step 5b): a small segment whose border runs mostly along one larger object segment is a
piece of it and joins it; a small object standing on the support (its border mostly against the plane) stays."""

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.segmentation.segments import SegmentationParams, _merge_fragments


def _patch(x0, x1, y0, y1, step=0.01):
    xs, ys = np.meshgrid(np.arange(x0, x1 - 1e-9, step), np.arange(y0, y1 - 1e-9, step), indexing="ij")
    return np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)


def _scene():
    big = _patch(0.0, 0.20, 0.0, 0.15)  # 300 points: an object's face
    frag = _patch(0.20, 0.25, 0.0, 0.06)  # 30 points against the face only
    small = _patch(0.20, 0.28, 0.10, 0.18)  # 64 points: touches the face along 5 cm, stands on the table
    pts = np.vstack([big, frag, small])
    seg = np.repeat([0, 1, 2], [len(big), len(frag), len(small)])
    pairs = cKDTree(pts).query_pairs(r=0.018, output_type="ndarray")
    # the small object's outline (but where it meets the face) borders the support plane
    s = pts[seg == 2]
    rim = (np.isclose(s[:, 0], 0.27) | np.isclose(s[:, 1], 0.10) | np.isclose(s[:, 1], 0.17))
    near_plane = np.zeros(len(pts), dtype=bool)
    near_plane[np.flatnonzero(seg == 2)[rim]] = True
    return pts, seg, pairs, near_plane


def test_fragment_joins_the_segment_it_borders_and_a_small_object_stays():
    pts, seg, pairs, near_plane = _scene()
    out, merges = _merge_fragments(seg, pairs, near_plane, max_points=100, share=0.5)
    assert merges == 1
    assert np.all(out[seg == 1] == 0)  # the fragment is now part of the face's segment
    assert np.all(out[seg == 2] == 2) and np.all(out[seg == 0] == 0)


def test_fragment_size_and_off_switch():
    pts, seg, pairs, near_plane = _scene()
    out, merges = _merge_fragments(seg, pairs, near_plane, max_points=30, share=0.5)  # 30 points: not under 30
    assert merges == 0 and np.array_equal(out, seg)
    assert SegmentationParams().fragment_points > 0
    SegmentationParams(fragment_points=0).validate()  # 0 = off is valid
