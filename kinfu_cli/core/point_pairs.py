"""Neighbour-pair searches with a bound on their size, checked before the search, and the groups pairs link.

A k-d tree's pair search within a radius holds every pair it finds at once: a radius spanning the cloud makes
N^2 / 2 pairs (a 0.1 M point surface at 10 m: 5e9 pairs, and out of memory after 17 GB) instead of an answer. The
number is estimated first from PAIR_SAMPLE sampled points' neighbour counts (a dual-tree count, milliseconds even
for a radius spanning the cloud) and a search over MAX_POINT_PAIRS is refused with the caller's error.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import ConfigError, KinfuError

# ~115 B a pair at the peak of the costliest caller (segmentation's adjacency: scipy's pair vector, the (E, 2)
# array, LCCP's per-pair arrays and graphs; the sample fused at 6.9 mm, adjacency_radius 0.16 m: 24 M pairs,
# 3.0 GB): 20 M pairs is ~2.3 GB. At the default settings the largest search of `kinfu segment` holds 0.94 M pairs
# on the fused sample (saliency's isolation), 0.50 M on rgbd-tabletop-box and 4.2 M on the 7-Scenes kitchen
# (bridges at 5 cm); a radius spanning the cloud makes N^2 / 2 (the sample at 10 m: 2.3e9 pairs, 17 GB).
MAX_POINT_PAIRS = 20_000_000
PAIR_SAMPLE = 1000  # points whose neighbours within the radius are counted for the estimate


def estimated_pairs(tree: cKDTree, radius: float, queries: np.ndarray | None = None, p: float = 2.0) -> float:
    """Estimated number of point pairs within `radius` in the tree (each pair once, a point not with itself); with
    `queries`, of (query, tree point) pairs instead (what query_ball_point returns in all). From PAIR_SAMPLE of
    the points (or queries) sampled at random with a fixed seed, so the same cloud gives the same answer."""
    own = queries is None
    pool = tree.data if own else np.asarray(queries, dtype=np.float64).reshape(-1, tree.m)
    n = len(pool)
    if n == 0 or (own and n < 2):
        return 0.0
    m = min(n, PAIR_SAMPLE)
    pick = np.random.default_rng(0).choice(n, m, replace=False) if m < n else np.arange(n)
    within = float(cKDTree(pool[pick]).count_neighbors(tree, radius, p=p))  # (sample, any) pairs
    if own:
        return (within - m) * n / m / 2  # itself included once per sampled point; each pair seen from both ends
    return within * n / m


def check_pair_count(tree: cKDTree, radius: float, *, what: str, hint: str, parameter: str | None = None,
                     error: type[KinfuError] = ConfigError, queries: np.ndarray | None = None, p: float = 2.0,
                     limit: int | None = None) -> float:
    """The estimated pairs (`estimated_pairs`), or `error` naming `parameter` when they would be more than
    `limit` (default MAX_POINT_PAIRS). what: the tree's points as the message calls them ("surface points");
    hint: what was expected, or which input is doubtful when the radius comes from the data."""
    limit = MAX_POINT_PAIRS if limit is None else limit
    expected = estimated_pairs(tree, radius, queries, p)
    if expected > limit:
        raise error(f"{radius:g} m joins about {expected:.3g} point pairs among the {tree.n} {what} "
                    f"(at most {limit:.3g}, beyond which the search runs out of memory); {hint}",
                    parameter=parameter)
    return expected


def bounded_pairs(points: np.ndarray | cKDTree, radius: float, *, what: str, hint: str,
                  parameter: str | None = None, error: type[KinfuError] = ConfigError, p: float = 2.0,
                  limit: int | None = None) -> np.ndarray:
    """cKDTree.query_pairs (E, 2) within `radius` over `points` (or a tree already built on them), after
    `check_pair_count` (its error when they would be more than `limit`)."""
    tree = points if isinstance(points, cKDTree) else cKDTree(np.asarray(points, dtype=np.float64))
    check_pair_count(tree, radius, what=what, hint=hint, parameter=parameter, error=error, p=p, limit=limit)
    return tree.query_pairs(r=radius, p=p, output_type="ndarray")


def pair_components(n: int, pairs: np.ndarray) -> np.ndarray:
    """Connected-component id (0..K-1) of each of n nodes over undirected pairs (E, 2): the groups a pair search
    links (a node in no pair is its own component)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    g = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[1].astype(np.int64)
