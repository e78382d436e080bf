"""Statistics of values per group (segment, tile) by one sort, for the segment and room-structure rules."""

from __future__ import annotations

import numpy as np


def group_percentile(values: np.ndarray, group: np.ndarray, k: int, q: float) -> np.ndarray:
    """np.percentile(values[group == g], q) (linear interpolation) for every group g in 0..k-1, by one sort;
    a group without values gives 0."""
    if len(values) == 0:
        return np.zeros(k)
    order = np.lexsort((values, group))
    v = values[order]
    cnt = np.bincount(group, minlength=k)
    start = np.concatenate([[0], np.cumsum(cnt)[:-1]])
    pos = q / 100.0 * (np.maximum(cnt, 1) - 1)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, np.maximum(cnt - 1, 0))
    frac = pos - lo
    idx_lo = np.minimum(start + lo, len(v) - 1)
    idx_hi = np.minimum(start + hi, len(v) - 1)
    return np.where(cnt > 0, v[idx_lo] * (1 - frac) + v[idx_hi] * frac, 0.0)
