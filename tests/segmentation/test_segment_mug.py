"""Object recall on the `objects` scenes (issue 12): a mug is not cut beside its handle, a box on a box still is,
and touching boxes of different heights are step-cut although the fused surface leaves a few up-facing points
between their tops.

Why: on tuning scenes (0, 1, 8-139) every face-plane cut (4b) that parted two real objects lifted a box off the
box under it; the wrong ones (a mug's handle with a slice of body, a box base sliced) left two pieces that both
stand on the support. Objects side by side are the step cuts' (4a), whose levels a few rounded-edge points had
hidden."""

from __future__ import annotations

import numpy as np

from tests.segmentation.box_clouds import box_faces, object_segments as _objects

STEP = 0.007  # about the fused clouds' spacing


def _table(step=STEP, half=0.25, hole=None):
    g = np.arange(-half, half, step)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    keep = np.ones(len(x), bool) if hole is None else ~hole(x, y)
    return np.c_[x[keep], y[keep], np.zeros(keep.sum())], np.tile([0.0, 0.0, 1.0], (keep.sum(), 1))


def _mug(r=0.036, height=0.107, hr=0.03, tube=0.011):
    """Surface points and outward normals of a mug (closed cylinder + half-torus handle on its +x side) on a table."""
    na, nz = int(2 * np.pi * r / STEP), int(height / STEP)
    a, z = (v.ravel() for v in np.meshgrid(np.arange(na) * 2 * np.pi / na, (np.arange(nz) + 0.5) * height / nz,
                                           indexing="ij"))
    pts = [np.c_[r * np.cos(a), r * np.sin(a), z]]
    nrm = [np.c_[np.cos(a), np.sin(a), 0 * a]]
    g = np.arange(-r, r + 1e-9, STEP)
    x, y = (v.ravel() for v in np.meshgrid(g, g))
    lid = np.hypot(x, y) < r - STEP / 2
    pts.append(np.c_[x[lid], y[lid], np.full(lid.sum(), height)])
    nrm.append(np.tile([0.0, 0.0, 1.0], (lid.sum(), 1)))
    nu, nv = int(2 * np.pi * hr / STEP), int(2 * np.pi * tube / STEP) + 1
    u, v = (w.ravel() for w in np.meshgrid(np.arange(nu) * 2 * np.pi / nu, np.arange(nv) * 2 * np.pi / nv,
                                           indexing="ij"))
    p = np.c_[r + (hr + tube * np.cos(v)) * np.cos(u), tube * np.sin(v), height / 2 + (hr + tube * np.cos(v)) * np.sin(u)]
    out = np.hypot(p[:, 0], p[:, 1]) > r
    pts.append(p[out])
    nrm.append(np.c_[np.cos(v) * np.cos(u), np.sin(v), np.cos(v) * np.sin(u)][out])
    tp, tn = _table(hole=lambda x, y: np.hypot(x, y) <= r)
    return np.concatenate(pts + [tp]), np.concatenate(nrm + [tn])


def _box_faces(lo, hi, skip=()):
    return box_faces(lo, hi, STEP, skip)


def test_mug_is_not_face_cut_beside_its_handle_but_a_box_on_a_box_is():
    """A permissive face-plane cut (concave share 0.1, as exact faces need) used to cut the mug into three pieces
    standing side by side on the table; now each cut must leave one piece off the support."""
    pts, nrm = _mug()
    seg, objs = _objects(pts, nrm, cut_concave_fraction=0.1)
    assert len(objs) == 1 and seg.stats["plane_cuts"] == 0
    assert np.sum(seg.labels == objs[0]) >= 0.95 * np.sum(pts[:, 2] > 0.005)
    # a box on a box, flush with its +x face (one plane: LCCP alone joins them); the cut lifts the top box off
    base, top = ((-0.08, -0.06, 0.0), (0.08, 0.06, 0.08)), ((-0.02, -0.04, 0.08), (0.08, 0.04, 0.15))
    bp, bn = _box_faces(*base)
    keep = ~np.all((bp[:, :2] >= (-0.02, -0.04)) & (bp[:, :2] <= (0.08, 0.04)), axis=1) | (bp[:, 2] < 0.08 - 1e-9)
    tp, tn = _box_faces(*top)
    table = _table(hole=lambda x, y: (np.abs(x) <= 0.08) & (np.abs(y) <= 0.06))
    seg, objs = _objects(np.concatenate([bp[keep], tp, table[0]]), np.concatenate([bn[keep], tn, table[1]]),
                         cut_concave_fraction=0.1)
    assert len(objs) == 2 and seg.stats["plane_cuts"] >= 1
    upper = seg.labels[(seg.points[:, 2] > 0.09) & (seg.labels > 0)]
    lower = seg.labels[(seg.points[:, 2] < 0.07) & (seg.points[:, 2] > 0.01) & (seg.labels > 0)]
    assert len(np.unique(upper)) == 1 and len(np.unique(lower)) == 1 and upper[0] != lower[0]


def test_step_cut_sees_two_tops_through_a_few_points_between_them():
    """Touching boxes 12 and 10.5 cm tall: a fused surface leaves a few up-facing points on the step between the
    tops (the TSDF rounds its edge), which filled the gap between the two levels; levels are heights that many
    up-facing points share, so the step is still found."""
    a, b = ((-0.10, -0.05, 0.0), (0.0, 0.05, 0.12)), ((0.0, -0.05, 0.0), (0.08, 0.05, 0.105))
    ap, an = _box_faces(*a)
    bp, bn = _box_faces(*b, skip={(0, -1)})
    seen = ~((np.abs(ap[:, 0]) < 1e-9) & (ap[:, 2] < 0.105))  # a's face below b's top is hidden by b
    step = np.c_[np.full(4, 0.002), np.linspace(-0.03, 0.03, 4), np.linspace(0.108, 0.117, 4)]
    table = _table(hole=lambda x, y: (x >= -0.10) & (x <= 0.08) & (np.abs(y) <= 0.05))
    pts = np.concatenate([ap[seen], bp, step, table[0]])
    nrm = np.concatenate([an[seen], bn, np.tile([0.0, 0.0, 1.0], (4, 1)), table[1]])
    seg, objs = _objects(pts, nrm, cut_concave_fraction=None)
    assert len(objs) == 2 and seg.stats["step_cuts"] == 1
    inner = np.abs(seg.points[:, 1]) < 0.04
    la = seg.labels[inner & (seg.points[:, 0] < -0.01) & (seg.points[:, 2] > 0.01) & (seg.labels > 0)]
    lb = seg.labels[inner & (seg.points[:, 0] > 0.01) & (seg.points[:, 2] > 0.01) & (seg.labels > 0)]
    assert len(np.unique(la)) == 1 and len(np.unique(lb)) == 1 and la[0] != lb[0]
