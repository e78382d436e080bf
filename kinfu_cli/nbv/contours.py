"""Contour (frontier-next-to-surface) points for object-driven NBV, thesis ch. 3 (eqs. 3.2, 3.5-3.7).

A voxel e is a contour voxel when (3.2):
  1. it is known empty (w(e) >= W_th and v(e) > 0);
  2. one of its 6 face neighbours is unknown (w < W_th);
  3. one of its 18 face + edge neighbours is known occupied (w >= W_th and v <= 0).
Its frontier normal (3.5) is n_e = sum over the 26 neighbours c of w'(c) (c - e)/|c - e|, with (3.6)
w'(c) = -W_th for occupied c, else min(w(c) - W_th, W_th): unknown and occupied neighbours push the
normal away, known-empty ones pull it, so it points out into observed free space (the view direction).
Contour voxels are grouped by region growing (3.7): neighbours closer than `distance_th` whose normals
differ by less than `angle_th_deg` join one group (the printed "< A_th" on the dot product is read as
an angle threshold); groups wider than `max_group_size` are cut on a grid of that size so a long
frontier yields several viewpoints. Each group gives one contour point: mean position, mean normal.

Input is a ternary grid (labels 1/0/-1, known = observed) and optionally the fusion weights, so that
W_th applies; without weights every labelled voxel counts as known with weight 2 W_th.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.point_pairs import bounded_pairs, pair_components

_N6 = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=np.int64)
_N26 = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)],
                dtype=np.int64)
_N18 = np.array([o for o in _N26 if np.abs(o).sum() <= 2], dtype=np.int64)


@nb.njit(cache=True, inline="always")
def _is_contour(state, i, j, k, n6, n18):
    X, Y, Z = state.shape
    if state[i, j, k] != -1:
        return False
    unk = False
    for m in range(6):
        a, b, c = i + n6[m, 0], j + n6[m, 1], k + n6[m, 2]
        if a < 0 or b < 0 or c < 0 or a >= X or b >= Y or c >= Z:
            continue  # outside the grid is not evidence of anything
        if state[a, b, c] == 0:
            unk = True
            break
    if not unk:
        return False
    for m in range(18):
        a, b, c = i + n18[m, 0], j + n18[m, 1], k + n18[m, 2]
        if a < 0 or b < 0 or c < 0 or a >= X or b >= Y or c >= Z:
            continue
        if state[a, b, c] == 1:
            return True
    return False


@nb.njit(cache=True, parallel=True)
def _contour_kernel(state, n6, n18):
    """state int8: -1 known empty, 1 known occupied, 0 unknown. Returns contour voxel indices (M, 3)
    (two passes: count per x slice, then fill, so no full-size mask is allocated)."""
    X, Y, Z = state.shape
    counts = np.zeros(X, dtype=np.int64)
    for i in nb.prange(X):
        c = 0
        for j in range(Y):
            for k in range(Z):
                if _is_contour(state, i, j, k, n6, n18):
                    c += 1
        counts[i] = c
    offs = np.zeros(X + 1, dtype=np.int64)
    for i in range(X):
        offs[i + 1] = offs[i] + counts[i]
    out = np.empty((offs[X], 3), dtype=np.int64)
    for i in nb.prange(X):
        q = offs[i]
        for j in range(Y):
            for k in range(Z):
                if _is_contour(state, i, j, k, n6, n18):
                    out[q, 0] = i
                    out[q, 1] = j
                    out[q, 2] = k
                    q += 1
    return out


@nb.njit(cache=True, parallel=True)
def _frontier_normals(state, weights, use_weights, w_th, idx, n26):
    """Eq. 3.5/3.6 normals (unnormalised) for voxel indices idx (M, 3)."""
    M = idx.shape[0]
    X, Y, Z = state.shape
    out = np.zeros((M, 3))
    for q in nb.prange(M):
        i, j, k = idx[q, 0], idx[q, 1], idx[q, 2]
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for m in range(26):
            a, b, c = i + n26[m, 0], j + n26[m, 1], k + n26[m, 2]
            if a < 0 or b < 0 or c < 0 or a >= X or b >= Y or c >= Z:
                continue
            s = state[a, b, c]
            if s == 1:
                wp = -w_th
            else:
                if use_weights:
                    w = float(weights[a, b, c])
                else:
                    w = 2.0 * w_th if s == -1 else 0.0
                wp = min(w - w_th, w_th)
            norm = np.sqrt(float(n26[m, 0] ** 2 + n26[m, 1] ** 2 + n26[m, 2] ** 2))
            sx += wp * n26[m, 0] / norm
            sy += wp * n26[m, 1] / norm
            sz += wp * n26[m, 2] / norm
        out[q, 0] = sx
        out[q, 1] = sy
        out[q, 2] = sz
    return out


@dataclass
class Contours:
    """Grouped contour points: positions (M, 3) world, directions (M, 3) unit view directions (from the
    contour point towards where the sensor should be), sizes (M,) voxels per group; voxel_positions /
    voxel_normals / voxel_group are the ungrouped contour voxels."""

    positions: np.ndarray
    directions: np.ndarray
    sizes: np.ndarray
    voxel_positions: np.ndarray
    voxel_normals: np.ndarray
    voxel_group: np.ndarray

    def __len__(self) -> int:
        return int(len(self.positions))


def ternary_state(labels: np.ndarray, weights: np.ndarray | None = None, w_th: float = 5.0) -> np.ndarray:
    """int8 state: -1 known empty, 1 known occupied, 0 unknown (w < W_th when weights are given)."""
    lab = np.asarray(labels, dtype=np.int8)
    if weights is None:
        return lab
    w = np.asarray(weights)
    if w.shape != lab.shape:
        raise VolumeError(f"weights shape {w.shape} differs from labels shape {lab.shape}")
    return np.where(w >= w_th, lab, np.int8(0)).astype(np.int8)


def contour_voxels(labels: np.ndarray, weights: np.ndarray | None = None, w_th: float = 5.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(indices (M, 3) of contour voxels, their unit frontier normals (M, 3) in grid axes)."""
    if np.asarray(labels).ndim != 3:
        raise VolumeError(f"ternary labels must be 3-D, got shape {np.asarray(labels).shape}")
    if not w_th > 0:
        raise ConfigError(f"must be > 0, got {w_th}", parameter="w_th")
    state = ternary_state(labels, weights, w_th)
    # contour voxels touch an occupied voxel: only the box around occupied voxels (+ 2) can hold them
    box = []
    for axis in range(3):
        other = tuple(a for a in range(3) if a != axis)
        hit = np.flatnonzero(np.any(state == 1, axis=other))
        if hit.size == 0:
            return np.zeros((0, 3), np.int64), np.zeros((0, 3))
        box.append(slice(max(int(hit[0]) - 2, 0), min(int(hit[-1]) + 3, state.shape[axis])))
    box = tuple(box)
    offset = np.array([b.start for b in box], dtype=np.int64)
    sub = np.ascontiguousarray(state[box])
    idx = _contour_kernel(sub, _N6, _N18)
    if weights is None:
        wdummy = np.zeros((1, 1, 1), dtype=np.uint8)  # the fusion weights' type: one compiled kernel for both
        raw = _frontier_normals(sub, wdummy, False, float(w_th), idx, _N26)
    else:
        raw = _frontier_normals(sub, np.ascontiguousarray(np.asarray(weights)[box]), True, float(w_th), idx, _N26)
    idx = idx + offset
    norm = np.linalg.norm(raw, axis=1)
    ok = norm > 1e-9
    return idx[ok], raw[ok] / norm[ok, None]


def extract_contours(labels: np.ndarray, origin, voxel_size: float, *, weights: np.ndarray | None = None,
                     w_th: float = 5.0, distance_th: float | None = None, angle_th_deg: float = 30.0,
                     max_group_size: float = 0.05, min_group_voxels: int = 3) -> Contours:
    """Contour voxels grouped into contour points (see the module docstring).

    distance_th defaults to 1.75 voxels (the 26-neighbourhood); max_group_size (m) cuts long groups.
    """
    vs = float(voxel_size)
    idx, nrm = contour_voxels(labels, weights, w_th)
    pos = np.asarray(origin, dtype=np.float64) + (idx + 0.5) * vs
    empty = Contours(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), pos, nrm,
                     np.full(len(pos), -1, np.int64))
    if len(idx) == 0:
        return empty
    dth = 1.75 * vs if distance_th is None else float(distance_th)
    if distance_th is None:  # 1.75 voxels, the 26-neighbours: at most 13 pairs a voxel, whatever the volume
        pairs = cKDTree(pos).query_pairs(r=dth, output_type="ndarray")
    else:
        pairs = bounded_pairs(pos, dth, what="contour voxels", parameter="distance_th",
                              hint=f"expected a distance of a voxel or two (default 1.75 voxels, {1.75 * vs:g} m)")
    if len(pairs):
        similar = np.einsum("ij,ij->i", nrm[pairs[:, 0]], nrm[pairs[:, 1]]) > np.cos(np.radians(angle_th_deg))
        pairs = pairs[similar]
    comp = pair_components(len(pos), pairs)
    if max_group_size and max_group_size > 0:
        cell = np.floor(pos / max_group_size).astype(np.int64)
        key = np.column_stack([comp, cell])
        _, comp = np.unique(key, axis=0, return_inverse=True)
        comp = comp.ravel()
    k = int(comp.max()) + 1
    sizes = np.bincount(comp, minlength=k)
    keep = sizes >= min_group_voxels
    remap = np.full(k, -1, np.int64)
    remap[keep] = np.arange(int(keep.sum()))
    group = remap[comp]
    k2 = int(keep.sum())
    if k2 == 0:
        empty.voxel_group = group
        return empty
    m = group >= 0
    cnt = np.bincount(group[m], minlength=k2).astype(np.float64)
    P = np.stack([np.bincount(group[m], pos[m, a], minlength=k2) for a in range(3)], 1) / cnt[:, None]
    D = np.stack([np.bincount(group[m], nrm[m, a], minlength=k2) for a in range(3)], 1)
    dn = np.linalg.norm(D, axis=1)
    good = dn > 1e-9
    D[good] /= dn[good, None]
    D[~good] = np.array([0.0, 0.0, 1.0])
    return Contours(P, D, cnt.astype(np.int64), pos, nrm, group)
