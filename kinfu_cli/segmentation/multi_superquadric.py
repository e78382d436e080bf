"""Multi-superquadric model of a non-convex segment (Vezzani 2019 thesis, ch. 8.1, Algs. 4-6).

1. Superquadric tree (Alg. 4) of height H: every node holds a part of the cloud and its superquadric; it
   is cut by the plane through the part's barycentre perpendicular to its principal axis (the direction
   of largest spread, which is the thesis' "axis of maximum inertia" read as the axis the mass is spread
   along, so an elongated part is cut across its length), and each half is fitted. [ours, cut="volume", the
   default]: the root is instead cut where the cross-section changes, when its best `volume_cut` is clearly
   one (a mug's handle meets its body where no barycentre plane runs: every one cuts through the handle).
2. Splitting planes (Alg. 5), bottom-up from h = H-1: a node's plane is splitting when its children's
   superquadrics have `different_dimensions`; then the child closest to the node's brother (the children's
   uncle) is compared with that uncle, and the result decides the grandfather's plane (similar: not
   splitting, different: splitting), which its own test no longer overrides (Fig. 8.8: a coarse sibling
   differs even when the higher cut runs through a uniform region). A node decided that way still passes
   its own uncle test up (ours: else a badly fitted coarse node decides its parent's plane alone).
3. Final superquadrics (Alg. 6): the cloud is cut by the splitting planes (a plane acts on the region that
   holds its node, widened by every ancestor plane that is not splitting), regions below `min_points` join
   their nearest region, and each region reuses its tree superquadric when it equals a tree node's points,
   else gets a new fit.

Not in the thesis, our choices: the "contiguous" test (no tolerance given there) and the tie-break when
the two children of one node disagree about their grandfather (splitting wins: over-segmentation is still
usable for grasping, a missed part is not).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.segmentation.superquadric import SegmentError, SuperquadricFit, fit_superquadric

CONTIGUOUS_DEG = 35.0  # the centre link within this angle of a paired axis: the axes lie on one line
CUTS = ("volume", "barycentre")
# [ours] Alg. 4 with cut="volume": the root (a whole object) is cut at its best `volume_cut` (in its
# `box_frame`) instead of the barycentre when the two sides' boxes take less than VOLUME_CUT_RATIO of its box.
# Chosen on tuning seeds 100-104 of bench_multi_superquadric (the reported seeds are 0-2), root ratios: T
# 0.40-0.41, L 0.49-0.50, mug 0.72-0.73, bottle 0.76; one primitive: ellipsoid 0.90-0.91, sphere 0.91, box
# 0.91-0.97, capsule 0.91-0.93, cylinder 0.93-0.95, but a cone 0.61-0.73 (cut into a frustum and its tip).
# Only the root (VOLUME_CUT_DEPTH = 1): deeper nodes are open-shell pieces whose boxes shrink at a cut
# without any change of part; cutting them too (depth 6, principal frame) left single boxes exact only for
# mu >= 0.03 and cylinders for 0.06.
VOLUME_CUT_RATIO = 0.8
VOLUME_CUT_DEPTH = 1


@dataclass
class SQNode:
    """A tree node: its points (indices into the segment's cloud), superquadric, cut plane and children."""

    points: np.ndarray
    fit: SuperquadricFit | None
    depth: int
    plane: tuple[np.ndarray, np.ndarray] | None = None  # (point, normal)
    children: list["SQNode"] = field(default_factory=list)
    splitting: bool = False
    index: np.ndarray | None = None  # indices of `points` in the segment's cloud
    decided: bool = False  # set by a grandchild's uncle test (Alg. 5 lines 14-17): the own test is skipped
    in_plane: np.ndarray | None = None  # (3, 2): the cut plane's in-plane axes (the other two principal axes)

    def nodes(self) -> list["SQNode"]:
        """This node and all below it, depth first."""
        out = [self]
        for c in self.children:
            out += c.nodes()
        return out


@dataclass
class MultiSuperquadric:
    parts: list[SuperquadricFit]
    part_points: list[np.ndarray]
    tree: SQNode
    planes: list[tuple[np.ndarray, np.ndarray]]  # the splitting planes used
    refitted: list[bool] = field(default_factory=list)  # per part: True when Alg. 6 fitted a new superquadric
    mu: float = 0.0
    part_indices: list[np.ndarray] = field(default_factory=list)  # per part: indices into the finite points

    def to_json(self) -> dict:
        return {"parts": [p.to_json() for p in self.parts], "mu": self.mu, "refitted": list(self.refitted),
                "planes": [{"point": p.tolist(), "normal": n.tolist()} for p, n in self.planes]}


def paired_axes(a: SuperquadricFit, b: SuperquadricFit) -> tuple[int, ...]:
    """perm[i] = the axis of b parallel to axis i of a (the largest total |dot product|, thesis R_r^l)."""
    C = np.abs(a.superquadric.rotation.T @ b.superquadric.rotation)
    return max(itertools.permutations(range(3)), key=lambda p: sum(C[i, p[i]] for i in range(3)))


def contiguous_axis(a: SuperquadricFit, b: SuperquadricFit, perm: tuple[int, ...], mu: float) -> int:
    """The pair index i whose axes lie on one line with two extremes close, or -1.

    On one line: the line between the centres is within CONTIGUOUS_DEG of a's axis i. Extremes close: the
    gap between the facing ends along that axis is below max(mu, a quarter of the two semi-axes' sum)."""
    sa, sb = a.superquadric, b.superquadric
    link = sb.center - sa.center
    n = float(np.linalg.norm(link))
    if n < 1e-9:
        return -1
    along = sa.rotation.T @ link  # the link in a's frame
    i = int(np.argmax(np.abs(along)))
    if abs(along[i]) / n < np.cos(np.radians(CONTIGUOUS_DEG)):
        return -1
    reach = sa.size[i] + sb.size[perm[i]]
    return i if abs(abs(along[i]) - reach) < max(mu, 0.25 * reach) else -1


def plane_axis(a: SuperquadricFit, perm: tuple[int, ...], normal: np.ndarray) -> int:
    """The pair index i whose axis of a lies within CONTIGUOUS_DEG of the cut plane's normal, or -1."""
    cos = np.abs(a.superquadric.rotation.T @ (np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)))
    i = int(np.argmax(cos))
    return i if cos[i] >= np.cos(np.radians(CONTIGUOUS_DEG)) else -1


def cut_extents(points: np.ndarray, in_plane: np.ndarray) -> np.ndarray:
    """Full extents (2,) m of `points` along a cut plane's two in-plane axes (columns of `in_plane`, (3, 2)),
    robust 1-99 % range."""
    lo, hi = np.percentile(np.asarray(points, dtype=np.float64) @ in_plane, [1, 99], axis=0)
    return hi - lo


def different_dimensions(a: SuperquadricFit, b: SuperquadricFit, mu: float, normal: np.ndarray | None = None,
                         extents: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """Thesis differentDimensions: pair the parallel axes, skip the contiguous pair, and report whether any
    other pair's dimensions (full lengths, m) differ by `mu` or more.

    normal: the plane that cut a from b in the tree (siblings: their parent's plane; a nephew and its uncle:
    the grandfather's). Pieces on both sides of a cut are contiguous across it by construction, so the pair
    along the normal is the contiguous one ([ours]: the centre-distance test, used without a normal, fails
    exactly when it matters, on the coarse, overlapping fit of a region that holds two parts).
    extents: the two pieces' point extents along the cut plane (`cut_extents`); the superquadrics then
    differ only when these differ by mu too ([ours]: the fit of an open shell, a piece of a cylinder wall,
    can come out as a thin plate or a fat block while the points on both sides of the cut span the same)."""
    perm = paired_axes(a, b)
    skip = contiguous_axis(a, b, perm, mu) if normal is None else plane_axis(a, perm, normal)
    da, db = 2 * a.superquadric.size, 2 * b.superquadric.size
    fits_differ = any(abs(da[i] - db[perm[i]]) >= mu for i in range(3) if i != skip)
    if extents is None or not fits_differ:
        return fits_differ
    return bool(np.any(np.abs(np.asarray(extents[0]) - np.asarray(extents[1])) >= mu))


def _extents(a: "SQNode", b: "SQNode", cut: "SQNode") -> tuple[np.ndarray, np.ndarray] | None:
    """Both pieces' extents along the plane of `cut` (their parent, or the nephew's grandfather); None for a
    tree built by hand without points or in-plane axes."""
    if cut.in_plane is None or not len(a.points) or not len(b.points):
        return None
    return cut_extents(a.points, cut.in_plane), cut_extents(b.points, cut.in_plane)


# -------------------------------------------------------------------------------------------- Alg. 4
def _fit_or_none(points: np.ndarray, fit_kwargs: dict) -> SuperquadricFit | None:
    """The part's fit, None when degenerate. Unless the caller bounds the size, a semi-axis stays below
    0.6 x the part's largest extent: a cut part is an open shell, and a free fit of an open shell can
    grow into the open side (a half-disc fitted as a twice-wider shape), which fakes a dimension change."""
    kw = dict(fit_kwargs)
    if kw.get("max_size") is None and len(points) >= 3:
        centred = points - points.mean(axis=0)
        _, _, vt = np.linalg.svd(centred, full_matrices=False)
        local = centred @ vt.T
        kw["max_size"] = max(0.6 * float(np.ptp(local, axis=0).max()), 0.01)
    try:
        return fit_superquadric(points, **kw)
    except SegmentError:
        return None


def box_frame(points: np.ndarray) -> np.ndarray:
    """Axes (3, 3, columns) of a tight box around `points`: the principal axis of least spread, then the
    sides of the minimum-area rectangle around the points projected across it (one side lies along an edge
    of their convex hull). [ours]: an L's principal axes run diagonally, a box along them is loose, and a
    cut across them misses the junction."""
    c = np.asarray(points, dtype=np.float64) - np.mean(points, axis=0)
    _, v = np.linalg.eigh(np.cov(c.T))
    uv = c @ v[:, 1:]
    try:
        h = uv[ConvexHull(uv).vertices]
    except (QhullError, ValueError):
        return v[:, ::-1].copy()
    e = np.roll(h, -1, axis=0) - h
    ang = np.arctan2(e[:, 1], e[:, 0])
    cs, sn = np.cos(ang)[:, None], np.sin(ang)[:, None]
    area = np.ptp(h[:, 0] * cs + h[:, 1] * sn, axis=1) * np.ptp(h[:, 1] * cs - h[:, 0] * sn, axis=1)
    k = int(np.argmin(area))
    d1 = cs[k, 0] * v[:, 1] + sn[k, 0] * v[:, 2]
    return np.stack([v[:, 0], d1, np.cross(v[:, 0], d1)], axis=1)


def volume_cut(local: np.ndarray, min_points: int) -> tuple[int, float, float]:
    """The cut perpendicular to one of the frame's axes that minimises the summed volume of the two sides'
    bounding boxes (in that frame: `box_frame`), each side at least min_points: (axis, position
    along it, summed volume / the node's box volume). A part attached where the cross-section changes (a
    mug's handle, a bottle's neck) gives a ratio well below 1 at the junction; one convex primitive stays
    above about 0.92 (sphere 0.926, cylinder across its axis 0.95, box 1). (-1, 0, 1) when no cut fits.

    local: (N, 3) points in the node's box frame. Vectorised: per axis one sort and running min / max."""
    n = len(local)
    whole = float(np.prod(np.ptp(local, axis=0)))
    if n < 2 * min_points or whole <= 0:
        return -1, 0.0, 1.0
    best = (-1, 0.0, 1.0)
    i = np.arange(min_points - 1, n - min_points)  # the left side holds sorted points 0..i
    for k in range(3):
        s = local[np.argsort(local[:, k], kind="stable")]
        lo, hi = np.minimum.accumulate(s, axis=0), np.maximum.accumulate(s, axis=0)
        rlo, rhi = np.minimum.accumulate(s[::-1], axis=0)[::-1], np.maximum.accumulate(s[::-1], axis=0)[::-1]
        total = np.prod(hi[i] - lo[i], axis=1) + np.prod(rhi[i + 1] - rlo[i + 1], axis=1)
        j = int(np.argmin(total))
        if total[j] / whole < best[2]:
            best = (k, 0.5 * float(s[i[j], k] + s[i[j] + 1, k]), float(total[j] / whole))
    return best


def _build(pts: np.ndarray, index: np.ndarray, depth: int, height: int, min_points: int, fit_kwargs: dict,
           cut: str = "volume") -> SQNode:
    points = pts[index]
    node = SQNode(points, _fit_or_none(points, fit_kwargs), depth, index=index)
    if depth >= height or node.fit is None or len(index) < 2 * min_points:
        return node
    bary = points.mean(axis=0)
    _, v = np.linalg.eigh(np.cov((points - bary).T))
    k, origin = 2, bary  # the thesis' plane: through the barycentre, across the axis of largest spread
    if cut == "volume" and depth < VOLUME_CUT_DEPTH:
        frame = box_frame(points)
        axis, pos, ratio = volume_cut((points - bary) @ frame, min_points)
        if axis >= 0 and ratio < VOLUME_CUT_RATIO:
            k, origin, v = axis, bary + pos * frame[:, axis], frame
    normal = v[:, k]
    side = (points - origin) @ normal > 0
    if side.sum() < min_points or (~side).sum() < min_points:
        return node
    node.plane = (origin, normal)
    node.in_plane = v[:, [j for j in range(3) if j != k]]
    node.children = [_build(pts, index[~side], depth + 1, height, min_points, fit_kwargs, cut),
                     _build(pts, index[side], depth + 1, height, min_points, fit_kwargs, cut)]
    return node


def build_superquadric_tree(points: np.ndarray, *, height: int = 3, min_points: int = 30, cut: str = "volume",
                            **fit_kwargs) -> SQNode:
    """Alg. 4: the superquadric tree of height `height` (a node with fewer than 2 x min_points is a leaf).

    cut: "barycentre" is the thesis' plane at every node; "volume" ([ours], the default) cuts the root instead
    where the two sides' bounding boxes shrink most (`volume_cut`) when that is below VOLUME_CUT_RATIO of its
    box: where the cross-section changes (a mug's handle meets its body), which no barycentre plane may be."""
    if cut not in CUTS:
        raise ConfigError(f"expected one of {', '.join(CUTS)}, got {cut!r}", parameter="cut")
    if not 0 <= int(height) <= 6:
        raise ConfigError(f"expected 0..6, got {height}", parameter="height")
    if int(min_points) < 10:
        raise ConfigError(f"expected at least 10 points per region, got {min_points}", parameter="min_points")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise SegmentError(f"multi-superquadric: points must be (N, 3), got shape {pts.shape}")
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < int(min_points):
        raise SegmentError(f"multi-superquadric: the segment has {len(pts)} finite points, need at least "
                           f"min_points = {min_points}")
    root = _build(pts, np.arange(len(pts)), 0, int(height), int(min_points), fit_kwargs, cut)
    if root.fit is None:
        raise SegmentError(f"multi-superquadric: the segment ({len(pts)} points) cannot be fitted at all")
    return root


# -------------------------------------------------------------------------------------------- Alg. 5
def select_splitting_planes(root: SQNode, mu: float) -> None:
    """Alg. 5 on the tree (sets `splitting` on every node with a plane; the tree can be re-used per mu)."""
    if not mu > 0:
        raise ConfigError(f"must be > 0 m, got {mu}", parameter="mu")
    levels: dict[int, list[tuple[SQNode, SQNode | None, SQNode | None]]] = {}

    def walk(node: SQNode, parent: SQNode | None, brother: SQNode | None) -> None:
        node.splitting, node.decided = False, False
        levels.setdefault(node.depth, []).append((node, parent, brother))
        if len(node.children) == 2:
            walk(node.children[0], node, node.children[1])
            walk(node.children[1], node, node.children[0])

    walk(root, None, None)
    votes: dict[int, list[bool]] = {}
    for h in sorted(levels, reverse=True):
        for node, parent, uncle in levels[h]:
            if id(node) in votes:  # a grandchild's uncle test decided this plane
                node.splitting, node.decided = any(votes[id(node)]), True
            if len(node.children) != 2 or any(c.fit is None for c in node.children):
                continue
            left, right = node.children
            if not different_dimensions(left.fit, right.fit, mu, node.plane[1], _extents(left, right, node)):
                continue
            if not node.decided:
                node.splitting = True
            # the uncle test runs even when this plane was decided from below: the vote it passes up is about
            # the grandfather's plane, which a coarse (badly fitted) node would otherwise decide alone
            if parent is None or uncle is None or uncle.fit is None:
                continue
            nephew = min((left, right), key=lambda c: np.linalg.norm(
                c.fit.superquadric.center - uncle.fit.superquadric.center))
            votes.setdefault(id(parent), []).append(different_dimensions(
                nephew.fit, uncle.fit, mu, parent.plane[1], _extents(nephew, uncle, parent)))


# -------------------------------------------------------------------------------------------- Alg. 6
def _regions(node: SQNode, pts: np.ndarray, mask: np.ndarray) -> list[np.ndarray]:
    """Cut `mask` (a region holding this node) by the splitting planes at and below the node."""
    if len(node.children) != 2:
        return [mask]
    left, right = node.children
    if node.splitting:
        point, normal = node.plane
        side = (pts - point) @ normal > 0
        return _regions(left, pts, mask & ~side) + _regions(right, pts, mask & side)
    out = []
    for m in _regions(left, pts, mask):  # a plane that does not split: the children's planes cut the whole
        out += _regions(right, pts, m)
    return out


def _merge_small(regions: list[np.ndarray], pts: np.ndarray, min_points: int) -> list[np.ndarray]:
    """Regions below min_points join the region of their nearest point outside them."""
    regions = [r for r in regions if r.any()]
    while len(regions) > 1:
        sizes = [int(r.sum()) for r in regions]
        k = int(np.argmin(sizes))
        if sizes[k] >= min_points:
            break
        small = regions.pop(k)
        label = np.full(len(pts), -1)
        for j, r in enumerate(regions):
            label[r] = j
        others = np.flatnonzero(label >= 0)
        _, nn = cKDTree(pts[others]).query(pts[small], k=1)
        target = np.bincount(label[others[nn]], minlength=len(regions))
        regions[int(np.argmax(target))] = regions[int(np.argmax(target))] | small
    return regions


def final_superquadrics(root: SQNode, pts: np.ndarray, mu: float, min_points: int = 30, **fit_kwargs
                        ) -> MultiSuperquadric:
    """Alg. 6 for a tree whose planes were selected by `select_splitting_planes`."""
    pts = np.asarray(pts, dtype=np.float64)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    regions = _merge_small(_regions(root, pts, np.ones(len(pts), dtype=bool)), pts, int(min_points))
    by_points = {tuple(n.index.tolist()): n for n in root.nodes() if n.fit is not None}
    parts, part_points, refitted, part_indices = [], [], [], []
    for r in regions:
        idx = np.flatnonzero(r)
        node = by_points.get(tuple(idx.tolist()))
        fit = node.fit if node is not None else _fit_or_none(pts[idx], fit_kwargs)
        if fit is None:
            continue  # a degenerate sliver: its points stay unmodelled rather than badly modelled
        parts.append(fit)
        part_points.append(pts[idx])
        refitted.append(node is None)
        part_indices.append(idx)
    planes = [n.plane for n in root.nodes() if n.splitting]
    if not parts:
        parts, part_points, refitted, part_indices = [root.fit], [pts], [False], [np.arange(len(pts))]
    return MultiSuperquadric(parts, part_points, root, planes, refitted, float(mu), part_indices)


def fit_multi_superquadric(points: np.ndarray, *, height: int = 3, mu: float = 0.03, min_points: int = 30,
                           cut: str = "volume", **fit_kwargs) -> MultiSuperquadric:
    """Split a segment into superquadric parts, Algs. 4-6 (thesis H = 3, mu = 0.03 m for noisy clouds).

    cut: Alg. 4's planes, "volume" (default, ours) or the thesis' "barycentre" (`build_superquadric_tree`).
    fit_kwargs go to `fit_superquadric` for every node and region. Raises SegmentError when the segment has
    fewer than min_points points or cannot be fitted at all, ConfigError for a bad height, mu or min_points.
    """
    if not mu > 0:
        raise ConfigError(f"must be > 0 m, got {mu}", parameter="mu")
    pts = np.asarray(points, dtype=np.float64)
    root = build_superquadric_tree(pts, height=height, min_points=min_points, cut=cut, **fit_kwargs)
    select_splitting_planes(root, float(mu))
    return final_superquadrics(root, pts, float(mu), int(min_points), **fit_kwargs)
