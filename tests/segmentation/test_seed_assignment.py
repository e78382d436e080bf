"""The supervoxels' k-means step in numba chooses the seeds the numpy form (its reference) chooses."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from kinfu_cli.segmentation.seed_assignment import assign_to_seeds


@pytest.mark.parametrize("with_colour", [True, False])
def test_same_seeds_as_the_numpy_form(with_colour):
    rng = np.random.default_rng(5)
    n, k = 20000, 600
    pts, col = rng.random((n, 3)), rng.random((n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    sp, sc, sn = rng.random((k, 3)), rng.random((k, 3)), nrm[:k]
    _, cand = cKDTree(sp).query(pts, k=8)
    ws, wn, wc = 62.5, 1.0, 1.0 if with_colour else 0.0
    dx = pts[:, None, :] - sp[cand]
    dist = ws * np.einsum("ijk,ijk->ij", dx, dx) + wn * (1.0 - np.einsum("ik,ijk->ij", nrm, sn[cand]))
    if with_colour:
        dist += wc * np.linalg.norm(col[:, None, :] - sc[cand], axis=2)
    expected = cand[np.arange(n), np.argmin(dist, axis=1)]
    got = assign_to_seeds(pts, nrm, cand, sp, sn, ws, wn, col if with_colour else None, sc if with_colour else None,
                          wc)
    assert np.array_equal(got, expected)
    # ties go to the first candidate, as argmin's
    same = np.repeat(sp[:1], 2, axis=0)
    assert assign_to_seeds(pts[:3], nrm[:3], np.array([[1, 0]] * 3), same, np.repeat(sn[:1], 2, axis=0), ws,
                           wn).tolist() == [1, 1, 1]
