"""The one surface sampler: points on the mesh, uniform over its area, reproducible."""

import numpy as np
import open3d as o3d
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.sampling import sample_surface, sample_triangles, surface_area


def _box():
    m = o3d.geometry.TriangleMesh.create_box(0.4, 0.2, 0.1)
    return np.asarray(m.vertices), np.asarray(m.triangles)


def test_samples_lie_on_the_surface_uniformly_with_outward_normals():
    v, f = _box()
    assert surface_area(v, f) == pytest.approx(2 * (0.08 + 0.04 + 0.02))
    pts, nrm = sample_surface(v, f, spacing=0.005, seed=3)
    assert len(pts) == round(0.28 / 0.005 ** 2)
    centre = np.array([0.2, 0.1, 0.05])
    on_face = np.isclose(pts, 0.0, atol=1e-12) | np.isclose(pts, [0.4, 0.2, 0.1], atol=1e-12)
    assert on_face.any(axis=1).all()
    assert np.all(np.einsum("ij,ij->i", nrm, pts - centre) > 0) and np.allclose(np.linalg.norm(nrm, axis=1), 1)
    top = np.isclose(pts[:, 2], 0.1)
    assert top.mean() == pytest.approx(0.08 / 0.28, abs=0.01)  # share of the area
    again, _ = sample_surface(v, f, spacing=0.005, seed=3)
    assert np.array_equal(pts, again)


def test_counts_caps_and_errors():
    v, f = _box()
    assert len(sample_surface(v, f, spacing=0.001, max_samples=1000)[0]) == 1000
    assert len(sample_triangles(v, f, 7)[0]) == 7
    assert len(sample_triangles(v, f[:0], 7)[0]) == 0
    with pytest.raises(ConfigError, match="spacing"):
        sample_surface(v, f, spacing=0.0)
