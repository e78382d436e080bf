"""Concave plane cuts (segments.concave_plane_cuts): two touching same-colour boxes whose front faces are one
plane are one LCCP segment; the cut along the taller box's face separates them. Step cuts (segments.step_cuts):
the step between their tops separates them too; a box on a box and two boxes of one height are not step-cut."""

from __future__ import annotations

import numpy as np

from tests.segmentation.box_clouds import box_faces, object_segments as _objects

STEP = 0.01


def _boxes_on_table(boxes, hidden):
    """Surface points + normals of boxes standing on a table (z = 0), minus the faces listed in hidden."""
    pts, nrm = [], []
    x = np.arange(-0.4, 0.4, STEP)
    t = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    inside = np.zeros(len(t), bool)
    for lo, hi in boxes:
        inside |= np.all((t >= np.asarray(lo[:2])) & (t <= np.asarray(hi[:2])), axis=1)
    pts.append(np.c_[t[~inside], np.zeros((~inside).sum())])
    nrm.append(np.tile([0.0, 0.0, 1.0], ((~inside).sum(), 1)))
    for k, (lo, hi) in enumerate(boxes):
        p, n = box_faces(lo, hi, STEP, skip={(axis, side) for j, axis, side in hidden if j == k})
        pts.append(p)
        nrm.append(n)
    return np.concatenate(pts), np.concatenate(nrm)


def test_touching_twins_are_cut_along_the_taller_face():
    a = ((-0.10, -0.05, 0.0), (0.0, 0.05, 0.12))
    b = ((0.0, -0.05, 0.0), (0.08, 0.05, 0.09))
    pts, nrm = _boxes_on_table([a, b], hidden={(1, 0, -1)})
    seen = ~((np.abs(pts[:, 0]) < 1e-9) & (pts[:, 2] < 0.09))  # the touching faces: a's side above b stays
    pts, nrm = pts[seen], nrm[seen]
    _, merged = _objects(pts, nrm, cut_concave_fraction=None, step_min_height=0)
    assert len(merged) == 1  # LCCP alone: the coplanar front and back faces join them
    # exact box faces: only the pairs right at the crease are concave (11 % of the separated pairs); a fused
    # surface rounds the crease over a few voxels (40-58 % on the synth objects scenes, default 0.3)
    seg, objs = _objects(pts, nrm, cut_concave_fraction=0.1, step_min_height=0)  # the face-plane cut alone
    assert len(objs) == 2 and seg.stats["plane_cuts"] >= 1
    for lo, hi in (a, b):
        own = np.all((seg.points > np.asarray(lo) + 0.005) & (seg.points < np.asarray(hi) - 0.005), axis=1)
        own |= np.all((seg.points >= np.asarray(lo)) & (seg.points <= np.asarray(hi)), axis=1) & (seg.labels > 0)
        ids, counts = np.unique(seg.labels[own & (seg.labels > 0)], return_counts=True)
        assert counts.max() >= 0.9 * counts.sum()  # each box is (almost all) one segment
    pa = np.all((seg.points >= a[0]) & (seg.points <= (a[1][0] - 0.006, 0.05, 0.12)), axis=1) & (seg.labels > 0)
    pb = np.all((seg.points >= (0.006, -0.05, 0.0)) & (seg.points <= b[1]), axis=1) & (seg.labels > 0)
    assert set(np.unique(seg.labels[pa])).isdisjoint(np.unique(seg.labels[pb]))


def _box_labels(seg, box):
    """Object labels of the points strictly inside one box's faces (1 cm in from its edges)."""
    lo, hi = np.asarray(box[0]), np.asarray(box[1])
    own = np.all((seg.points >= lo) & (seg.points <= hi), axis=1) & (seg.labels > 0)
    own &= np.all((seg.points[:, :2] > lo[:2] + 0.01) & (seg.points[:, :2] < hi[:2] - 0.01), axis=1)
    return seg.labels[own]


def test_step_cut_parts_touching_boxes_of_different_heights():
    """Without the face-plane cut, the step between the two tops (12 vs 9 cm) parts the twins along the taller
    box's face; each box is one segment."""
    a = ((-0.10, -0.05, 0.0), (0.0, 0.05, 0.12))
    b = ((0.0, -0.05, 0.0), (0.08, 0.05, 0.09))
    pts, nrm = _boxes_on_table([a, b], hidden={(1, 0, -1)})
    seen = ~((np.abs(pts[:, 0]) < 1e-9) & (pts[:, 2] < 0.09))
    seg, objs = _objects(pts[seen], nrm[seen], cut_concave_fraction=None)
    assert len(objs) == 2 and seg.stats["step_cuts"] == 1
    la, lb = _box_labels(seg, a), _box_labels(seg, b)
    assert len(np.unique(la)) == 1 and len(np.unique(lb)) == 1 and la[0] != lb[0]
    _, objs = _objects(pts[seen], nrm[seen], cut_concave_fraction=None, step_min_height=0.04)  # step 3 cm
    assert len(objs) == 1


def test_step_cut_leaves_a_box_on_a_box_and_a_flat_top():
    """A box on a larger box has the base's top all round it (no vertical plane parts the two tops), and two
    touching boxes of one height have one top: neither is step-cut."""
    base = ((-0.08, -0.06, 0.0), (0.08, 0.06, 0.08))
    top = ((-0.04, -0.03, 0.08), (0.04, 0.03, 0.15))
    pts, nrm = _boxes_on_table([base, top], hidden={(1, 2, -1)})
    under = (np.abs(pts[:, 2] - 0.08) < 1e-9) & np.all(np.abs(pts[:, :2]) <= (0.04, 0.03), axis=1)
    seg, _ = _objects(pts[~under], nrm[~under], cut_concave_fraction=None)
    assert seg.stats["step_cuts"] == 0
    a = ((-0.10, -0.05, 0.0), (0.0, 0.05, 0.10))
    b = ((0.0, -0.05, 0.0), (0.08, 0.05, 0.10))
    pts, nrm = _boxes_on_table([a, b], hidden={(0, 0, 1), (1, 0, -1)})
    seg, objs = _objects(pts, nrm, cut_concave_fraction=None)
    assert seg.stats["step_cuts"] == 0 and len(objs) == 1
