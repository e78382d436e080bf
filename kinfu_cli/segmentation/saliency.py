"""Segment saliency, thesis eq. 3.8-3.12: isolation F(S) x roundness d_min / d_max of the oriented box.

- Oriented bounding box (3.8-3.10): frame at the segment mean, axes = eigenvectors of the point
  covariance; d_k = max c'_k - min c'_k.
- Isolation (3.11): F(S) = |{c in S : every point o outside S is farther than B_th}| / |S|
  (B_th = 0.02 m): penalises small and noisy segments and segments glued to others.
- Saliency (3.12): F(S) * d_min / d_max.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.point_pairs import bounded_pairs


@dataclass
class OrientedBox:
    center: np.ndarray  # (3,) world centre of the box (not the mean)
    axes: np.ndarray  # (3, 3) columns = unit axes, largest spread first, right-handed
    extents: np.ndarray  # (3,) full side lengths d_k along the axes (m)

    def to_json(self) -> dict:
        return {"center": self.center.tolist(), "axes": self.axes.T.tolist(), "extents": self.extents.tolist()}


def oriented_box(points: np.ndarray) -> OrientedBox:
    """PCA box of eq. 3.8-3.10 (a single point or a line gives zero extents, never an error)."""
    pts = np.asarray(points, dtype=np.float64)
    mu = pts.mean(axis=0)
    if len(pts) < 2:
        return OrientedBox(mu, np.eye(3), np.zeros(3))
    w, vecs = np.linalg.eigh(np.cov((pts - mu).T))
    vecs = vecs[:, ::-1].copy()
    if np.linalg.det(vecs) < 0:
        vecs[:, 2] *= -1
    local = (pts - mu) @ vecs
    lo, hi = local.min(axis=0), local.max(axis=0)
    return OrientedBox(mu + vecs @ ((lo + hi) / 2), vecs, hi - lo)


ISOLATION_HINT = "expected B_th about the gap that sets objects apart (default 0.02 m)"  # its pair bound's error


def isolation(points: np.ndarray, labels: np.ndarray, b_th: float = 0.02, tree: cKDTree | None = None
              ) -> dict[int, float]:
    """F(S) per label (eq. 3.11). Points labelled -1 count as "other" points for every segment. tree: a k-d
    tree already built on `points` (the pipeline's, which checked b_th on it before segmenting)."""
    if not b_th > 0:
        raise ConfigError(f"must be > 0 m, got {b_th}", parameter="b_th")
    pts = np.asarray(points, dtype=np.float64)
    lab = np.asarray(labels)
    # B_th is SegmentOptions.isolation_threshold, the name its callers set
    pairs = bounded_pairs(pts if tree is None else tree, b_th, what="surface points", parameter="isolation_threshold",
                          hint=ISOLATION_HINT)
    touching = np.zeros(len(pts), dtype=bool)
    if len(pairs):
        cross = lab[pairs[:, 0]] != lab[pairs[:, 1]]
        touching[pairs[cross, 0]] = True
        touching[pairs[cross, 1]] = True
    out = {}
    for s in np.unique(lab):
        if s == -1:
            continue
        m = lab == s
        out[int(s)] = float(1.0 - touching[m].mean())
    return out


@dataclass
class SegmentSaliency:
    id: int
    n_points: int
    centroid: np.ndarray
    box: OrientedBox
    isolation: float
    roundness: float
    saliency: float
    bounding_radius: float  # radius of the sphere around the box centre holding every point (m)


def segment_saliency(points: np.ndarray, labels: np.ndarray, *, b_th: float = 0.02,
                     exclude: tuple[int, ...] = (-1,), tree: cKDTree | None = None) -> list[SegmentSaliency]:
    """Saliency of every segment (labels not in `exclude`), sorted by decreasing saliency; tree: as `isolation`."""
    pts = np.asarray(points, dtype=np.float64)
    lab = np.asarray(labels)
    iso = isolation(pts, lab, b_th, tree)
    out = []
    for s, f in iso.items():
        if s in exclude:
            continue
        p = pts[lab == s]
        box = oriented_box(p)
        dmax = float(box.extents.max())
        rnd = float(box.extents.min() / dmax) if dmax > 0 else 0.0
        rad = float(np.linalg.norm(p - box.center, axis=1).max()) if len(p) else 0.0
        out.append(SegmentSaliency(int(s), int(len(p)), p.mean(axis=0), box, f, rnd, f * rnd, rad))
    out.sort(key=lambda x: (-x.saliency, x.id))
    return out
