"""Floating pieces (segments step 5c): a piece seen wholly above the table that touches nothing rests on a part
the view hides (a drill's barrel over its handle), so it joins the segment under it; an object standing behind
another, its lower part hidden, is beside it, not over it, and stays apart."""

from __future__ import annotations

import numpy as np

from tests.segmentation.box_clouds import box_faces, object_segments

STEP = 0.01


def _table(exclude) -> tuple[np.ndarray, np.ndarray]:
    x = np.arange(-0.4, 0.4, STEP)
    t = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    out = np.zeros(len(t), bool)
    for lo, hi in exclude:
        out |= np.all((t >= np.asarray(lo[:2])) & (t <= np.asarray(hi[:2])), axis=1)
    return np.c_[t[~out], np.zeros((~out).sum())], np.tile([0.0, 0.0, 1.0], ((~out).sum(), 1))


def _cloud(parts, hidden_below=None):
    """Table plus the boxes' faces (bottoms hidden); points of box k under hidden_below[k] m are hidden too."""
    pts, nrm = [_table([(lo, hi) for lo, hi in parts])[0]], [_table([(lo, hi) for lo, hi in parts])[1]]
    for k, (lo, hi) in enumerate(parts):
        p, n = box_faces(lo, hi, STEP)
        keep = p[:, 2] >= (hidden_below or {}).get(k, -1.0)
        pts.append(p[keep])
        nrm.append(n[keep])
    return np.concatenate(pts), np.concatenate(nrm)


def test_a_barrel_over_its_hidden_handle_joins_it():
    handle = ((-0.04, -0.03, 0.0), (0.02, 0.03, 0.12))
    barrel = ((-0.06, -0.025, 0.15), (0.14, 0.025, 0.2))  # 3 cm gap: the handle's top is hidden under it
    pts, nrm = _cloud([handle, barrel])
    seg, objects = object_segments(pts, nrm)
    assert len(objects) == 1
    assert seg.stats["floating_joined"] == 1
    assert np.all(seg.labels[pts[:, 2] > 0.01] == objects[0])


def test_an_object_behind_another_stays_apart():
    front = ((-0.05, -0.05, 0.0), (0.05, 0.05, 0.1))
    back = ((-0.05, 0.09, 0.0), (0.05, 0.19, 0.2))  # 4 cm behind, its lower 6 cm hidden by the front box
    pts, nrm = _cloud([front, back], hidden_below={1: 0.06})
    seg, objects = object_segments(pts, nrm)
    assert len(objects) == 2
    assert seg.stats["floating_joined"] == 0
