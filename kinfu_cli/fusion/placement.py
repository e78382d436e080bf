"""Default grid placement: the volume centred on what the first frames observe (back-projected depth)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from kinfu_cli.core.errors import VolumeError


def backproject(depth: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray, stride: int = 4,
                min_depth: float = 0.0, max_depth: float = np.inf) -> np.ndarray:
    """World points (N, 3) of valid depth pixels, every `stride`-th pixel in both directions."""
    d = np.asarray(depth, dtype=np.float64)[::stride, ::stride]
    v, u = np.mgrid[0:depth.shape[0]:stride, 0:depth.shape[1]:stride]
    ok = np.isfinite(d) & (d > min_depth) & (d <= max_depth) & (d > 0)
    z = d[ok]
    x = (u[ok] - K[0, 2]) / K[0, 0] * z
    y = (v[ok] - K[1, 2]) / K[1, 1] * z
    pc = np.stack([x, y, z], axis=1)
    return pc @ np.asarray(T_world_camera)[:3, :3].T + np.asarray(T_world_camera)[:3, 3]


def observed_center(frames: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]], min_depth: float = 0.0,
                    max_depth: float = np.inf, low: float = 50.0, high: float = 50.0) -> np.ndarray:
    """Centre of the points seen in (depth, K, T) frames: per axis the mean of the low and high percentiles
    (default the median, which stays on the observed scene when a floor or wall extends far away)."""
    pts = [backproject(d, K, T, min_depth=min_depth, max_depth=max_depth) for d, K, T in frames]
    pts = [p for p in pts if len(p)]
    if not pts:
        raise VolumeError("cannot place the volume: the first frames have no valid depth (give the grid origin "
                          "x,y,z)", parameter="origin")
    p = np.concatenate(pts)
    lo = np.percentile(p, low, axis=0)
    hi = np.percentile(p, high, axis=0)
    return 0.5 * (lo + hi)


def default_origin(frames, size, min_depth: float = 0.0, max_depth: float = np.inf) -> np.ndarray:
    """Grid minimum corner so that a grid of `size` (metres, one or three values) is centred on the observed
    points of `frames` ((depth, K, T_world_camera) tuples)."""
    size = np.broadcast_to(np.asarray(size, dtype=np.float64), (3,))
    return observed_center(frames, min_depth, max_depth) - 0.5 * size
