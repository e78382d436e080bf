"""The support is the table even when the floor around it holds most of the points: a plane under the share
rule qualifies by its span (SUPPORT_MIN_SPAN both ways, one connected patch), while the tops of objects at one
height, however far apart, do not. Before, the bundled sample's floor (86 k points) was the support and its table
(11 k) an object that swallowed two of the four objects standing on it."""

from __future__ import annotations

import numpy as np

from kinfu_cli.segmentation.segments import SegmentationParams, detect_support_plane, segment_cloud

STEP = 0.01


def _patch(x0, x1, y0, y1, z, normal=(0.0, 0.0, 1.0)):
    x, y = np.meshgrid(np.arange(x0, x1, STEP), np.arange(y0, y1, STEP), indexing="ij")
    p = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], 1)
    return p, np.tile(normal, (len(p), 1))


def _box(cx, cy, base, side, height):
    """Top and four sides of a box standing on z = base (outward normals)."""
    h = side / 2
    parts = [_patch(cx - h, cx + h, cy - h, cy + h, base + height)]
    zs = np.arange(base + STEP, base + height, STEP)
    t = np.arange(-h, h, STEP)
    for axis, sign in ((0, 1), (0, -1), (1, 1), (1, -1)):
        a, b = np.meshgrid(t, zs, indexing="ij")
        p = np.zeros((a.size, 3))
        p[:, axis] = (cx if axis == 0 else cy) + sign * h
        p[:, 1 - axis] = (cy if axis == 0 else cx) + a.ravel()
        p[:, 2] = b.ravel()
        n = np.zeros(3)
        n[axis] = sign
        parts.append((p, np.tile(n, (len(p), 1))))
    return parts


def _scene(boxes=((-0.15, 0.0), (0.15, 0.05)), table=0.6):
    """A 2.4 x 2.4 m floor, a table top of `table` m at 0.7 m, and 12 cm boxes on it."""
    parts = [_patch(-1.2, 1.2, -1.2, 1.2, 0.0), _patch(-table / 2, table / 2, -table / 2, table / 2, 0.7)]
    for cx, cy in boxes:
        parts += _box(cx, cy, 0.7, 0.12, 0.12)
    pts = np.concatenate([p for p, _ in parts])
    nrm = np.concatenate([n for _, n in parts])
    keep = ~((np.abs(pts[:, 0]) < table / 2) & (np.abs(pts[:, 1]) < table / 2) & (pts[:, 2] < 0.5))  # shadow
    return pts[keep], nrm[keep]


def test_a_table_over_a_larger_floor_is_the_support():
    pts, nrm = _scene()
    params = SegmentationParams(up=(0.0, 0.0, 1.0))
    info: dict = {}
    plane, inl = detect_support_plane(pts, nrm, params, info)
    assert np.isclose(-plane[3], 0.7, atol=0.005), (plane, info)
    assert "span" in info["qualified"]
    seg = segment_cloud(pts, nrm, params)
    objects = [lab for lab in np.unique(seg.labels) if lab > 0]
    assert len(objects) == 2, np.unique(seg.labels, return_counts=True)
    for lab in objects:  # each box is one segment of its own, the table is not among them
        z = seg.points[seg.labels == lab, 2]
        assert z.min() > 0.7 and z.max() < 0.83


def test_tops_of_objects_far_apart_are_no_support():
    """Four boxes' tops at one height span 0.5 m but are four patches: the table stays the support."""
    pts, nrm = _scene(boxes=((-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)), table=0.8)
    info: dict = {}
    plane, _ = detect_support_plane(pts, nrm, SegmentationParams(up=(0.0, 0.0, 1.0)), info)
    assert np.isclose(-plane[3], 0.7, atol=0.005), (plane, info)
