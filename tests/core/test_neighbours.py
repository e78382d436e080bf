"""The one nearest-neighbour transfer within a distance (labels in evaluation, colours in segmentation) against a
brute-force search."""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.neighbours import transfer_nearest


def test_transfer_nearest_matches_brute_force_and_leaves_far_rows():
    rng = np.random.default_rng(3)
    src, dst = rng.uniform(0, 1, (300, 3)), rng.uniform(0, 1, (500, 3))
    values = rng.uniform(0, 1, (300, 3))
    d = np.linalg.norm(dst[:, None] - src[None], axis=2)
    near, nearest = d.min(1), d.argmin(1)
    for radius in (0.02, 0.05, 0.2):
        out = np.full((500, 3), -7.0)
        dist = transfer_nearest(src, values, dst, radius, out)
        hit = near <= radius
        assert 0 < hit.sum() < 500 or radius == 0.2
        np.testing.assert_allclose(dist[hit], near[hit], rtol=1e-12)
        assert np.all(np.isinf(dist[~hit]))
        assert np.array_equal(out[hit], values[nearest[hit]]) and np.all(out[~hit] == -7.0)
    labels = np.full(500, -1, dtype=np.int64)  # a 1-D values column
    transfer_nearest(src, np.arange(300, dtype=np.int32), dst, 0.05, labels)
    assert np.array_equal(labels, np.where(near <= 0.05, nearest, -1))
