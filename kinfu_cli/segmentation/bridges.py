"""Bridges across unknown space: two segments of one surface cut apart by a band the camera never measured join.

Structured-light depth is missing in bands on black plastic, glossy print and in the projector's shadow (5-20 px on
real RealSense views, wider than the segmentation's adjacency radius): a face then reaches the segmentation as two
pieces with nothing between them. The ternary volume tells this gap from the one between two objects: across a
band of missing depth the voxels were never observed (UNKNOWN), whereas between two objects the camera saw the
table or the background through the gap, so the voxels there are observed EMPTY.

Rule (`join_across_unknown`): two segments that do not touch (no points within the adjacency radius) but come
within `max_gap` join when, for their nearest border point pairs (up to PAIRS_PER_SEGMENT_PAIR of them):
- the straight segment between the two points crosses no observed empty voxel away from its ends (at most
  `max_empty_share` of the samples farther than END_MARGIN voxels from both ends), and mostly unknown ones;
- the surfaces continue each other: the two points' normals within `max_normal_deg`, and the line between them
  within `max_normal_deg` / 2 + SLOPE_SLACK_DEG of both tangent planes;
- their colours near the two points are close (chroma distance at most `max_colour`; skipped without colours).
A pair of segments joins when the majority of its checked point pairs pass. Thresholds: tuning seeds (household
0-5, objects 0, 1, 8-11), see `BridgeParams`.

Vectorised numpy and scipy k-d trees; no loops over points or voxels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import EMPTY, UNKNOWN, TernaryGrid
from kinfu_cli.core.point_pairs import bounded_pairs, check_pair_count, pair_components
from kinfu_cli.segmentation.color_distances import color_distance

PAIRS_PER_SEGMENT_PAIR = 5
END_MARGIN = 1.5  # voxels: samples this close to either end lie in the measured surface's own band
SLOPE_SLACK_DEG = 15.0
NEIGHBOURHOOD = 0.02  # m: normals and colours near a border point are averaged over this radius

# labels of world points (M, 3) -> int8 (M,) in {1 occupied, 0 unknown, -1 empty}, and the voxel size
SpaceQuery = tuple[Callable[[np.ndarray], np.ndarray], float]


@dataclass
class BridgeParams:
    max_gap: float = 0.05  # m
    max_empty_share: float = 0.2
    min_unknown_share: float = 0.5
    max_normal_deg: float = 40.0
    max_colour: float = 0.1  # chroma distance (color_distances' "chroma": blind to shading, which differs across a
    # face's band of missing depth as much as between faces)


def space_query(labels: np.ndarray, origin: np.ndarray, voxel_size: float) -> SpaceQuery:
    """A SpaceQuery over dense ternary labels (X, Y, Z) int8; points outside the grid are unknown."""
    return TernaryGrid(np.asarray(labels, dtype=np.int8), np.asarray(origin, dtype=np.float64).reshape(3),
                       float(voxel_size)).labels_at, float(voxel_size)


def _nearest_pairs(points: np.ndarray, normals: np.ndarray, seg: np.ndarray, max_gap: float, touch: float,
                   min_cos: float) -> tuple[np.ndarray, np.ndarray]:
    """Point pairs (i, j) (indices into points) of different segments within max_gap whose normals agree
    (cosine >= min_cos: the two sides of one face, not a face and the next one across an edge), up to
    PAIRS_PER_SEGMENT_PAIR nearest per segment pair, only for segment pairs with no points closer than touch;
    and the segment pair key of each."""
    idx = np.flatnonzero(seg >= 0)
    # max_gap is SegmentationParams.bridge_gap, the name its callers set
    pairs = bounded_pairs(points[idx], max_gap, what="segmented points", parameter="bridge_gap",
                          hint=f"expected a gap of a few centimetres (default {BridgeParams.max_gap:g} m)")
    if len(pairs) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    pairs = idx[pairs]
    a, b = seg[pairs[:, 0]], seg[pairs[:, 1]]
    pairs, a, b = pairs[a != b], a[a != b], b[a != b]
    k = int(seg.max()) + 1
    key = np.minimum(a, b) * k + np.maximum(a, b)
    d = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    order = np.lexsort((d, key))
    pairs, key, d = pairs[order], key[order], d[order]
    first = np.r_[True, key[1:] != key[:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(len(key)), 0))
    apart = d[start] >= touch  # the group's nearest pair is its first
    pairs, key = pairs[apart], key[apart]
    agree = np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) >= min_cos
    pairs, key = pairs[agree], key[agree]
    first = np.r_[True, key[1:] != key[:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(len(key)), 0))
    keep = np.arange(len(key)) - start < PAIRS_PER_SEGMENT_PAIR
    return pairs[keep], key[keep]


def _local_means(points: np.ndarray, values: np.ndarray, seg: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Mean of values (colours) over the points of the same segment within NEIGHBOURHOOD of each point index in
    at: one speck of shading or print does not decide."""
    tree = cKDTree(points)
    # NEIGHBOURHOOD is fixed: only a cloud far denser than a voxel's spacing holds that many points within it
    check_pair_count(tree, NEIGHBOURHOOD, queries=points[at], what="surface points", error=VolumeError,
                     hint=f"expected about one surface point per voxel, not a cloud this dense "
                          f"(its points within {NEIGHBOURHOOD:g} m of the bridge ends are averaged)")
    near = tree.query_ball_point(points[at], r=NEIGHBOURHOOD)
    lens = np.array([len(n) for n in near])
    rows = np.repeat(np.arange(len(at)), lens)
    cols = np.concatenate(near).astype(np.int64) if len(near) else np.zeros(0, np.int64)
    same = seg[cols] == seg[at][rows]
    rows, cols = rows[same], cols[same]
    cnt = np.bincount(rows, minlength=len(at)).astype(np.float64)
    out = np.stack([np.bincount(rows, values[cols, c], minlength=len(at)) for c in range(values.shape[1])], 1)
    return out / np.maximum(cnt, 1.0)[:, None]


def _gap_shares(p: np.ndarray, q: np.ndarray, space: SpaceQuery) -> tuple[np.ndarray, np.ndarray]:
    """Share of empty and of unknown samples along each segment p -> q, away from its ends."""
    query, vs = space
    length = np.linalg.norm(q - p, axis=1)
    n = int(np.ceil(length.max() / (vs / 2))) + 1 if len(p) else 1
    t = np.linspace(0.0, 1.0, n + 1)
    x = p[:, None, :] + t[None, :, None] * (q - p)[:, None, :]
    from_end = np.minimum(t[None, :], 1.0 - t[None, :]) * length[:, None]
    inner = from_end > END_MARGIN * vs
    lab = query(x.reshape(-1, 3)).reshape(len(p), -1)
    cnt = np.maximum(inner.sum(axis=1), 1)
    empty = ((lab == EMPTY) & inner).sum(axis=1) / cnt
    unknown = ((lab == UNKNOWN) & inner).sum(axis=1) / cnt
    # a gap shorter than the end margins holds no inner sample: nothing says it was unobserved
    return np.where(inner.any(axis=1), empty, 1.0), np.where(inner.any(axis=1), unknown, 0.0)


def join_across_unknown(seg: np.ndarray, points: np.ndarray, normals: np.ndarray, colors: np.ndarray | None,
                        space: SpaceQuery, touch: float, params: BridgeParams | None = None
                        ) -> tuple[np.ndarray, int]:
    """Segment ids (-1 = none kept) after joining segments across unknown gaps (module docstring), and the
    number of joins. touch: the adjacency radius (segments that close were cut on purpose)."""
    params = params or BridgeParams()
    seg = np.asarray(seg)
    if np.sum(seg >= 0) == 0:
        return seg, 0
    pairs, key = _nearest_pairs(points, normals, seg, params.max_gap, touch,
                                np.cos(np.radians(params.max_normal_deg)))
    if len(pairs) == 0:
        return seg, 0
    i, j = pairs[:, 0], pairs[:, 1]
    ends = np.r_[i, j]
    ni, nj = normals[i], normals[j]  # the cloud's normals are smoothed over a voxel already; a local mean at a
    # border point near an edge would blend the two faces
    d = points[j] - points[i]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    slope = np.sin(np.radians(params.max_normal_deg / 2 + SLOPE_SLACK_DEG))
    ok = (np.einsum("ij,ij->i", ni, nj) >= np.cos(np.radians(params.max_normal_deg)))
    ok &= (np.abs(np.einsum("ij,ij->i", d, ni)) <= slope) & (np.abs(np.einsum("ij,ij->i", d, nj)) <= slope)
    if colors is not None:
        col = _local_means(points, colors, seg, ends)
        ok &= color_distance(col[:len(i)], col[len(i):], "chroma") <= params.max_colour
    empty, unknown = _gap_shares(points[i], points[j], space)
    ok &= (empty <= params.max_empty_share) & (unknown >= params.min_unknown_share)
    keys, inv = np.unique(key, return_inverse=True)
    passed = np.bincount(inv, ok.astype(np.float64)) / np.bincount(inv)
    join = keys[passed > 0.5]
    if len(join) == 0:
        return seg, 0
    k = int(seg.max()) + 1
    comp = pair_components(k, np.stack([join // k, join % k], 1))
    return np.where(seg >= 0, comp[np.maximum(seg, 0)], -1), int(len(join))


def volume_space(volume) -> SpaceQuery:
    """The SpaceQuery of a fusion TernaryVolume or a TernaryGrid: their own `labels_at`."""
    return volume.labels_at, float(volume.voxel_size)
