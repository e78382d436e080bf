"""Multi-superquadric model of a non-convex segment (Vezzani 2019 thesis, ch. 8.1, Algs. 4-6).

1. Superquadric tree (Alg. 4) of height H: every node holds a part of the cloud and its superquadric;
   it is cut by the plane through the part's barycentre whose normal is the part's principal axis (the
   direction of largest spread, so an elongated part is cut across its length), and each half is fitted.
2. Splitting planes (Alg. 5, simplified): a node's plane is "splitting" when its two children's
   superquadrics have different dimensions: their axes are paired by direction, the pair most aligned
   with the line between the two centres is skipped (the "contiguous" axes, which a cut always
   shortens), and the others differ by more than `mu` (m).
3. Regions (Alg. 6): walking down from the root, a non-splitting plane keeps its node whole (its
   superquadric is reused); a splitting one continues into both children.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.segmentation.superquadric import SegmentError, SuperquadricFit, fit_superquadric


@dataclass
class SQNode:
    points: np.ndarray
    fit: SuperquadricFit | None
    depth: int
    plane: tuple[np.ndarray, np.ndarray] | None = None  # (point, normal)
    children: list["SQNode"] = field(default_factory=list)
    splitting: bool = False


@dataclass
class MultiSuperquadric:
    parts: list[SuperquadricFit]
    part_points: list[np.ndarray]
    tree: SQNode
    planes: list[tuple[np.ndarray, np.ndarray]]  # the splitting planes used

    def to_json(self) -> dict:
        return {"parts": [p.to_json() for p in self.parts],
                "planes": [{"point": p.tolist(), "normal": n.tolist()} for p, n in self.planes]}


def different_dimensions(a: SuperquadricFit, b: SuperquadricFit, mu: float) -> bool:
    """True when two superquadrics differ by more than `mu` along a paired, non-contiguous axis."""
    A, B = a.superquadric.rotation, b.superquadric.rotation
    C = np.abs(A.T @ B)
    perm = max(itertools.permutations(range(3)), key=lambda p: sum(C[i, p[i]] for i in range(3)))
    link = b.superquadric.center - a.superquadric.center
    n = np.linalg.norm(link)
    skip = int(np.argmax(np.abs(A.T @ (link / n)))) if n > 1e-9 else -1
    da = 2 * a.superquadric.size
    db = 2 * b.superquadric.size
    return any(abs(da[i] - db[perm[i]]) > mu for i in range(3) if i != skip)


def _build(points: np.ndarray, depth: int, height: int, min_points: int, fit_kwargs: dict) -> SQNode:
    try:
        fit = fit_superquadric(points, **fit_kwargs)
    except SegmentError:
        fit = None
    node = SQNode(points, fit, depth)
    if depth >= height or fit is None or len(points) < 2 * min_points:
        return node
    mu_ = points.mean(axis=0)
    w, v = np.linalg.eigh(np.cov((points - mu_).T))
    normal = v[:, -1]
    side = (points - mu_) @ normal > 0
    if side.sum() < min_points or (~side).sum() < min_points:
        return node
    node.plane = (mu_, normal)
    node.children = [_build(points[~side], depth + 1, height, min_points, fit_kwargs),
                     _build(points[side], depth + 1, height, min_points, fit_kwargs)]
    return node


def _mark(node: SQNode, mu: float) -> None:
    for c in node.children:
        _mark(c, mu)
    if len(node.children) == 2 and all(c.fit is not None for c in node.children):
        node.splitting = different_dimensions(node.children[0].fit, node.children[1].fit, mu)


def _regions(node: SQNode, parts: list, planes: list) -> None:
    if node.splitting:
        planes.append(node.plane)
        for c in node.children:
            _regions(c, parts, planes)
    else:
        parts.append(node)


def fit_multi_superquadric(points: np.ndarray, *, height: int = 3, mu: float = 0.03, min_points: int = 30,
                           **fit_kwargs) -> MultiSuperquadric:
    """Split a segment into superquadric parts (thesis H = 3, mu = 0.03 m for noisy clouds)."""
    if height < 0 or height > 6:
        raise ConfigError(f"expected 0..6, got {height}", parameter="height")
    if not mu > 0:
        raise ConfigError(f"must be > 0 m, got {mu}", parameter="mu")
    pts = np.asarray(points, dtype=np.float64)
    root = _build(pts, 0, int(height), int(min_points), fit_kwargs)
    if root.fit is None:
        raise SegmentError(f"multi-superquadric: the segment ({len(pts)} points) cannot be fitted at all")
    _mark(root, float(mu))
    nodes: list[SQNode] = []
    planes: list = []
    _regions(root, nodes, planes)
    return MultiSuperquadric([n.fit for n in nodes], [n.points for n in nodes], root, planes)
