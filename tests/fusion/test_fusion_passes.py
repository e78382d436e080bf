"""The fusion kernels' helper passes (depth clipping, work list) and the colour pass against plain numpy rules."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.camera import preset_intrinsics
from kinfu_cli.fusion import kernels as kn
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import box_scene
from kinfu_cli.sim.sensor import DepthSensor
from tests.fusion.test_volume import projective_samples

W, H = 320, 240
VS = 0.008


@pytest.fixture(scope="module")
def frames():
    K = preset_intrinsics("kinect_v1", W, H)
    sensor = DepthSensor(K, W, H, noise=False)
    scene = box_scene()
    rng = np.random.default_rng(5)
    out = []
    for T in orbit_poses(5, radius=0.8, height=0.6, span_deg=200):
        d, c = sensor.render(scene, T)
        d = d.copy()
        for _ in range(8):  # holes of no reading
            r, u = rng.integers(0, H - 20), rng.integers(0, W - 20)
            d[r:r + rng.integers(2, 20), u:u + rng.integers(2, 20)] = 0
        out.append((d, c, K, T))
    return out


@pytest.mark.parametrize("lo,hi", [(0.0, 4.0), (0.3, 3.7), (0.1, 1e300), (0.0, np.inf)])
def test_clean_depth_is_the_numpy_rule(lo, hi):
    """NaN, +-inf and readings outside [lo, hi] become 0, compared in float32 as numpy does (bounds that are not
    float32 numbers included)."""
    rng = np.random.default_rng(0)
    d = rng.uniform(-1, 6, (48, 64)).astype(np.float32)
    d[::7, ::3] = np.nan
    d[::11, ::5] = np.inf
    d[::13, ::2] = -np.inf
    d[0, :3] = [np.float32(0.3), np.float32(3.7), np.nextafter(np.float32(3.7), np.float32(9))]
    with np.errstate(over="ignore"):
        ok = np.isfinite(d) & (d >= lo) & (d <= hi)
    ref = np.where(ok, d, np.float32(0)).astype(np.float32)
    out = kn.clean_depth(d, lo, hi)
    assert out.dtype == np.float32 and np.array_equal(out, ref)
    assert 0 < np.count_nonzero(out) < out.size


def test_work_list_matches_the_classes(frames):
    """work_list returns the blocks with work and the VOXEL blocks without storage, in block order, and the
    counts."""
    vol = TernaryVolume(size=(0.96, 0.96, 0.4), voxel_size=VS, origin=(-0.48, -0.48, -0.06), min_depth=0.1,
                        truncation=0.03, color=False)
    d, c, K, T = frames[0]
    vol.integrate(d, K, T)  # some blocks get storage
    rng = np.random.default_rng(1)
    cls = rng.choice(np.array([kn.SKIP, kn.CARVE, kn.VOXEL], np.uint8), size=int(np.prod(vol.nb)), p=[0.5, 0.2, 0.3])
    bidx = vol.block_idx.reshape(-1)
    work, new_b, n_carve, n_voxel = kn.work_list(cls, bidx)
    assert np.array_equal(work, np.flatnonzero(cls))
    assert np.array_equal(new_b, np.flatnonzero((cls == kn.VOXEL) & (bidx < 0))) and new_b.size > 0
    assert new_b.size < n_voxel == np.count_nonzero(cls == kn.VOXEL)
    assert n_carve == np.count_nonzero(cls == kn.CARVE)


def _mean_colour_reference(shape, origin, vs, trunc, max_w, frames):
    """The projective rule with the running-mean colour of voxels within about a voxel of the surface, dense and
    in plain numpy (float64 geometry): black = never coloured takes the sample, else alpha = max(1 / w, 0.1)."""
    idx = np.indices(shape).reshape(3, -1).T
    pts = origin + (idx + 0.5) * vs
    w = np.zeros(len(pts), dtype=np.int64)
    col = np.zeros((len(pts), 3), dtype=np.float64)
    band = min(1.0, 1.2 * vs / trunc)
    for d, c, K, T in frames:
        ok, u, r, t = projective_samples(pts, d, K, T, trunc)
        w[ok] = np.minimum(w[ok] + 1, max_w)
        paint = ok & (np.abs(t) < band)
        fresh = ~col[paint].any(axis=1)
        alpha = np.where(fresh, 1.0, np.maximum(1.0 / w[paint], 0.1))[:, None]
        sample = c[r[paint], u[paint]].astype(np.float64)
        col[paint] = np.minimum(255.0, np.floor(col[paint] + alpha * (sample - col[paint]) + 0.5))
    return col.reshape(*shape, 3), w.reshape(shape)


def test_mean_colour_equals_dense_reference(frames):
    """The colour pass colours the same voxels as the plain rule (within about a voxel of the surface), with
    the same colour up to float32 rounding."""
    shape, origin, trunc, max_w = (120, 120, 50), np.array([-0.48, -0.48, -0.06]), 0.03, 64
    vol = TernaryVolume(size=np.array(shape) * VS, voxel_size=VS, origin=origin, truncation=trunc,
                        max_weight=max_w, min_depth=0.0, color=True)
    for d, c, K, T in frames:
        vol.integrate(d, K, T, c)
    c_ref, w_ref = _mean_colour_reference(shape, origin, VS, trunc, max_w, frames)
    _, w, col = vol.tsdf_weights(color=True)
    painted, painted_ref = col.any(axis=-1), c_ref.any(axis=-1)
    assert painted_ref.sum() > 5000  # the surfaces of the scene got colour
    assert (painted == painted_ref).mean() > 0.9999
    both = painted & painted_ref & (w == w_ref)
    diff = np.abs(col[both].astype(int) - c_ref[both].astype(int))
    assert (diff <= 1).mean() > 0.999 and diff.mean() < 0.05
