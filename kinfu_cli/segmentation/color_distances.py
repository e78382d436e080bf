"""Colour distances of segmentation's colour tests (LCCP's T_lccp, Flood Fill's T_ff, the joins across unknown gaps).

The thesis measures RGB distance (eqs. 4.14-4.15); lighting and a camera's gain scale a face's colour, which moves
it far in RGB, so the default is the chromaticity's distance, blind to such a scale.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.errors import ConfigError

# the colour distances of T_lccp (eq. 4.15) and T_ff (eq. 4.14), see color_distance
COLOR_DISTANCES = ("rgb", "chroma", "angle")


def chromaticity(c: np.ndarray) -> np.ndarray:
    """Chromaticities rgb / (r + g + b) of colours (N, 3) (the colour's direction; black, sum ~ 0, is grey)."""
    c = np.maximum(np.asarray(c, dtype=np.float64), 0.0)
    s = c.sum(axis=1, keepdims=True)
    return np.where(s > 1e-6, c / np.maximum(s, 1e-6), 1.0 / 3.0)


def color_distance(c1: np.ndarray, c2: np.ndarray, kind: str = "rgb") -> np.ndarray:
    """Row-wise distance (N,) of colours (N, 3) RGB in [0, 1]. "rgb": Euclidean (the thesis's eqs. 4.14-4.15).
    Lighting scales a face's colour (Lambert shading, a camera's gain), which moves it far in RGB; the other two
    ignore such a scale: "chroma", the Euclidean distance of the chromaticities rgb / (r + g + b) (0 to sqrt(2));
    "angle", the angle between the colour vectors (radians, 0 to pi / 2). Black has no hue: it is grey to both."""
    return feature_distance(color_features(c1, kind), color_features(c2, kind), kind)


def color_features(c: np.ndarray, kind: str) -> np.ndarray:
    """The colours in the space color_distance measures `kind` in: RGB itself, else their chromaticities.
    Computed once per point or supervoxel, then indexed by the pairs."""
    if kind == "rgb":
        return c
    if kind not in COLOR_DISTANCES:
        raise ConfigError(f"expected one of {', '.join(COLOR_DISTANCES)}, got {kind!r}", parameter="color_distance")
    return chromaticity(c)


def feature_distance(u: np.ndarray, v: np.ndarray, kind: str) -> np.ndarray:
    """Row-wise distance of color_features rows: the angle between them for "angle", else Euclidean."""
    if kind != "angle":
        return np.linalg.norm(u - v, axis=1)
    cos = np.einsum("ij,ij->i", u, v) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1), 1e-12)
    return np.arccos(np.clip(cos, -1.0, 1.0))
