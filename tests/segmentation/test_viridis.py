"""saliency.ply's viridis without matplotlib: the stored table looked up as matplotlib does."""

from __future__ import annotations

import numpy as np
from matplotlib import colormaps

from kinfu_cli.segmentation.outputs import viridis


def test_matches_matplotlib_at_256_even_values_and_anywhere():
    even = np.linspace(0, 1, 256)
    assert np.abs(viridis(even) - np.asarray(colormaps["viridis"](even))[:, :3]).max() <= 1 / 255
    # between the entries, at both ends and beyond them (clipped) it is matplotlib's lookup, not an interpolation
    x = np.r_[np.random.default_rng(0).uniform(-0.2, 1.2, 5000), 0.0, 1.0, 1 / 256, 255 / 256, -1e-9]
    assert np.array_equal(viridis(x), np.asarray(colormaps["viridis"](x))[:, :3])
