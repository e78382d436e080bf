"""Depth filters: range, bilateral, Kinect V2 shadow (Alg. 5) and veil (eq. 3.19) filters."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from kinfu_cli.errors import ConfigError
from kinfu_cli.fusion import filters
from kinfu_cli.fusion.synthetic import default_K

W, H = 320, 240
BASELINE = 0.08


def _scene():
    """Camera at the origin looking along +z: a box 1 m away in front of a wall 2.5 m away."""
    scene = o3d.t.geometry.RaycastingScene()
    wall = o3d.geometry.TriangleMesh.create_box(4.0, 4.0, 0.01).translate((-2.0, -2.0, 2.5))
    box = o3d.geometry.TriangleMesh.create_box(0.3, 0.3, 0.3).translate((-0.15, -0.15, 1.0))
    for m in (wall, box):
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(m))
    return scene


def _cast(scene, origins, dirs):
    rays = np.concatenate([origins, dirs], axis=-1).reshape(-1, 6).astype(np.float32)
    return scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().reshape(origins.shape[:-1])


@pytest.fixture(scope="module")
def rendered():
    K = default_K(W, H)
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    dirs = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((H, W))], axis=-1)
    scene = _scene()
    t = _cast(scene, np.zeros_like(dirs), dirs)
    depth = np.where(np.isfinite(t), t, 0).astype(np.float32)  # z = t for z-normalised directions
    P = dirs * depth[..., None]
    # shadow truth: the emitter (at x = -BASELINE) does not see the point
    E = np.array([-BASELINE, 0.0, 0.0])
    to_p = P - E
    dist = np.linalg.norm(to_p, axis=-1)
    t_e = _cast(scene, np.broadcast_to(E, P.shape).copy(), to_p / dist[..., None])
    shadow = (depth > 0) & (t_e < dist - 0.01)
    return depth, K, shadow


def test_range_filter_and_bilateral_keep_invalid_invalid(rendered):
    depth, K, _ = rendered
    d = depth.copy()
    d[0, :10] = np.nan
    r = filters.range_filter(d, 0.5, 2.0)
    assert np.all(r[0, :10] == 0)
    assert np.all((r == 0) | ((r >= 0.5) & (r <= 2.0)))
    assert np.count_nonzero(r) == np.count_nonzero((depth >= 0.5) & (depth <= 2.0) & ~np.isnan(d))
    noisy = depth + np.random.default_rng(0).normal(0, 0.005, depth.shape).astype(np.float32) * (depth > 0)
    noisy[100:110, 100:110] = 0
    b = filters.bilateral(noisy)
    assert np.all(b[noisy == 0] == 0)
    flat = (depth > 2.4) & (np.abs(np.gradient(depth)[1]) < 1e-3) & (noisy > 0)
    assert np.std((b - depth)[flat]) < 0.6 * np.std((noisy - depth)[flat])


def test_shadow_filter_finds_the_emitter_shadow(rendered):
    depth, K, shadow = rendered
    assert shadow.sum() > 200  # the scene has a real shadow band
    mask = filters.shadow_mask(depth, K, BASELINE)
    recall = (mask & shadow).sum() / shadow.sum()
    fdr = (mask & ~shadow).sum() / max(mask.sum(), 1)
    assert recall > 0.9, recall  # misses are single boundary pixels of the band
    assert fdr < 0.05, fdr  # thesis Table 3.5: 4 % at 8 cm, 0 deg
    with pytest.raises(ConfigError):
        filters.shadow_mask(depth, K, 0.0)


def test_veil_filter_flags_mixed_pixels_only(rendered):
    depth, K, _ = rendered
    # on clean planes only pixels at a depth jump (the step runs along the viewing ray) are flagged
    jump = np.zeros(depth.shape, bool)
    for ax in (0, 1):
        dd = np.abs(np.diff(depth, axis=ax)) > 0.05
        if ax == 0:
            jump[:-1] |= dd
            jump[1:] |= dd
        else:
            jump[:, :-1] |= dd
            jump[:, 1:] |= dd
    clean = filters.veil_mask(depth, K)
    assert not (clean & ~jump).any()
    d = depth.copy()
    # mixed pixels: a column right of the box edge takes depths between box and wall
    row = slice(100, 140)
    edge = int(np.flatnonzero(np.abs(np.diff(depth[120])) > 1.0)[-1])
    d[row, edge + 1] = 1.75
    mask = filters.veil_mask(d, K)
    assert mask[row, edge + 1].mean() > 0.9
    out = filters.shadow_veil_filter(d, K, BASELINE)
    assert np.all(out[row, edge + 1] == 0)
