"""Object feet (segments._foot_refine): the fused surface rounds the corner where a box stands on the table; each
point of the rounded foot belongs to the surface it is nearer to (table below the 45 deg bisector, box above),
also when the table's colour has bled onto the whole foot."""

from __future__ import annotations

import numpy as np

from kinfu_cli.segmentation.segments import SegmentationParams, segment_cloud

STEP = 0.01
R = 0.007  # radius of the rounded foot (about one 6.9 mm voxel)
TABLE, BOX = (0.55, 0.40, 0.25), (0.15, 0.15, 0.75)


def _box_with_rounded_foot(half=0.06, height=0.12):
    """Table grid (z = 0) around a box, the box's sides and top, and a quarter circle of radius R at the foot of
    each side (centre R out from the side and R up; normals towards the centre). Returns points, normals, colours
    and the fillet angle of each foot point (0 on the table, 90 deg on the side; NaN elsewhere)."""
    pts, nrm, ang = [], [], []
    x = np.arange(-0.3, 0.3 + 1e-9, STEP)
    t = np.stack(np.meshgrid(x, x, indexing="ij"), -1).reshape(-1, 2)
    t = t[np.max(np.abs(t), axis=1) > half + R + 1e-9]
    pts.append(np.c_[t, np.zeros(len(t))])
    nrm.append(np.tile([0.0, 0.0, 1.0], (len(t), 1)))
    ang.append(np.full(len(t), np.nan))
    u = np.arange(-half + STEP / 2, half, STEP)
    z = np.arange(R, height, STEP)  # rows 1 cm apart from the fillet up, as the 1 cm surface cloud has them
    theta = np.radians(np.arange(5.0, 90.0, 10.0))
    for axis in (0, 1):
        for side in (-1.0, 1.0):
            other = 1 - axis
            g = np.stack(np.meshgrid(u, z, indexing="ij"), -1).reshape(-1, 2)
            p = np.zeros((len(g), 3))
            p[:, axis], p[:, other], p[:, 2] = side * half, g[:, 0], g[:, 1]
            n = np.zeros_like(p)
            n[:, axis] = side
            pts.append(p), nrm.append(n), ang.append(np.full(len(p), np.nan))
            # the fillet: distance to the table R (1 - cos), to the side R (1 - sin)
            th, uu = np.meshgrid(theta, u, indexing="ij")
            th, uu = th.ravel(), uu.ravel()
            p = np.zeros((len(th), 3))
            p[:, axis] = side * (half + R - R * np.sin(th))
            p[:, other] = uu
            p[:, 2] = R - R * np.cos(th)
            n = np.zeros_like(p)
            n[:, axis] = side * np.sin(th)  # towards the circle centre: out of the box, up from the table
            n[:, 2] = np.cos(th)
            pts.append(p), nrm.append(n), ang.append(np.degrees(th))
    top = np.stack(np.meshgrid(u, u, indexing="ij"), -1).reshape(-1, 2)
    pts.append(np.c_[top, np.full(len(top), height)])
    nrm.append(np.tile([0.0, 0.0, 1.0], (len(top), 1)))
    ang.append(np.full(len(top), np.nan))
    p, n, a = np.concatenate(pts), np.concatenate(nrm), np.concatenate(ang)
    col = np.where(np.isfinite(a)[:, None] | (p[:, 2] > 1e-9)[:, None], BOX, TABLE)
    return p, n / np.linalg.norm(n, axis=1, keepdims=True), col, a


def _labels(foot_radius, bleed):
    p, n, col, ang = _box_with_rounded_foot()
    if bleed:  # the table's colour on the whole foot (colour-depth misregistration)
        col = np.where(np.isfinite(ang)[:, None], TABLE, col)
    seg = segment_cloud(p, n, SegmentationParams(up=(0.0, 0.0, 1.0), foot_radius=foot_radius), colors=col)
    return seg.labels, ang


def test_foot_normals_point_away_from_the_corner():
    p, n, _, ang = _box_with_rounded_foot()
    foot = np.isfinite(ang)
    # a fillet point's normal points into the free space above the table and out of the box
    assert np.all(n[foot, 2] > 0)
    assert np.all(np.sum(n[foot, :2] * p[foot, :2], axis=1) > 0)


def test_each_foot_point_joins_the_nearer_surface():
    for bleed in (False, True):
        lab, ang = _labels(0.02, bleed)
        box = np.bincount(lab[lab > 0]).argmax()
        assert np.all(lab[ang < 40] == 0), bleed
        assert np.all(lab[ang > 50] == box), bleed
        assert len(np.unique(lab[lab > 0])) == 1


def test_without_the_foot_rule_bled_colour_pulls_the_foot_into_the_table():
    lab, ang = _labels(0.0, True)
    assert np.any(lab[ang > 50] == 0)
