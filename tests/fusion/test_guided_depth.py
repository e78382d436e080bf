"""The mode filter's guided depth (fusion/guided_depth.py, thesis Alg. 7): depth edges follow colour edges, and a
misregistered colour band at an object's border lands on the object less often than without it."""

from __future__ import annotations

import numpy as np

from kinfu_cli.fusion.guided_depth import guided_depth
from kinfu_cli.fusion.volume import TernaryVolume

RED, GREEN = (200, 30, 30), (30, 180, 40)
W, H, EDGE, SHIFT = 80, 60, 40, 2  # depth edge at column 40, the colour's 2 pixels to the left (misregistration)
NEAR, FAR = 1.0, 1.15


def _images(seed=0, noise=True, shift=SHIFT):
    rng = np.random.default_rng(seed)
    depth = np.full((H, W), NEAR, np.float32)
    depth[:, EDGE:] = FAR
    color = np.empty((H, W, 3), np.float32)
    color[:, :] = RED
    color[:, EDGE - shift:] = GREEN
    if noise:
        depth += rng.normal(0, 0.002, depth.shape).astype(np.float32)
        color += rng.normal(0, 2.0, color.shape)
    return depth, np.clip(color, 0, 255).astype(np.uint8)


def test_enhanced_depth_follows_the_colour_edge():
    depth, color = _images()
    e = guided_depth(depth, color)
    # green pixels with the near depth are pulled towards the far plane's depth, beyond the colour band of 1 cm
    # voxels (1.2 voxels, kernels.integrate_blocks); their neighbours across the colour edge much less
    band = e[:, EDGE - SHIFT:EDGE]
    assert np.median(band - NEAR) > 0.012
    assert np.median(np.abs(e[:, EDGE - SHIFT - 3] - NEAR)) < 0.006
    # away from both edges the depth is kept, and smoothed (the noise is 2 mm)
    inner = np.r_[0:EDGE - SHIFT - 4, EDGE + 6:W]
    truth = np.where(np.arange(W) < EDGE, NEAR, FAR)[inner]
    err, raw = e[:, inner] - truth, depth[:, inner] - truth
    assert np.abs(err).max() < 0.005 and np.sqrt(np.mean(err ** 2)) < 0.7 * np.sqrt(np.mean(raw ** 2))
    # no reading stays no reading; a pixel without a colour sample does not enter the windows either
    depth[10, 10] = 0.0
    ok = np.ones(H * W, np.uint8)
    ok[20 * W + 20] = 0
    e = guided_depth(depth, color, ok)
    assert e[10, 10] == 0.0 and e[20, 20] == 0.0 and abs(e[10, 11] - NEAR) < 0.003


def _fuse(guided: bool, shifts=(SHIFT,) * 6) -> TernaryVolume:
    """Six frames from one pose; shifts: each frame's colour misregistration, pixels."""
    K = np.array([[80.0, 0, W / 2], [0, 80.0, H / 2], [0, 0, 1]])
    vol = TernaryVolume(size=(1.0, 0.8, 0.5), voxel_size=0.005, origin=(-0.5, -0.4, 0.8), truncation=0.015,
                        min_depth=0.2, max_depth=2.0, color_mode="mode")
    vol.mode_guided = guided
    for k, shift in enumerate(shifts):
        depth, color = _images(seed=k, shift=shift)
        vol.integrate(depth, K, np.eye(4), color)
    return vol


def test_misregistered_band_is_narrower_with_the_guided_depth():
    """Surface voxels of the near (red) plane that end up green, the neighbour's colour band, when the colour is off
    by 2 pixels in 4 frames of 6 (the mode filter keeps the colour most frames saw) and right in the other 2."""
    counts = {}
    for guided in (False, True):
        vol = _fuse(guided, (SHIFT, SHIFT, 0, SHIFT, 0, SHIFT))
        tv, tw, tc = vol.tsdf_weights(color=True)
        z = vol.origin[2] + (np.arange(tv.shape[2]) + 0.5) * vol.voxel_size
        near = (tw > 0) & (np.abs(tv) < 0.5) & (np.abs(z - NEAR) < 0.0075)[None, None, :]
        green = tc[..., 1].astype(int) > tc[..., 0].astype(int)
        red = tc[..., 0].astype(int) > tc[..., 1].astype(int)
        counts[guided] = (int((near & green).sum()), int((near & red).sum()))
    (g0, r0), (g1, r1) = counts[False], counts[True]
    assert r1 > 0.9 * r0 > 1000  # the object keeps its own colour everywhere else
    assert g0 > 100 and g1 < 0.5 * g0  # without the guided depth the 2-pixel band (2.5 cm, 5 voxels) is green


def test_gated_samples_still_colour_a_voxel():
    """A voxel whose every colour sample the guided depth gated keeps a colour (the running mean of those samples),
    not black: the same voxels are coloured with and without the gate."""
    vols = {g: _fuse(g) for g in (False, True)}
    coloured = {g: v.tsdf_weights(color=True)[2].any(axis=-1) for g, v in vols.items()}
    assert coloured[False].sum() > 1000 and np.array_equal(coloured[True], coloured[False])
    vol = vols[True]
    n = vol.n_used
    gated_only = (vol.pool_hn[:n].sum(axis=-1) == 0) & vol.pool_c[:n].any(axis=-1)
    assert gated_only.sum() > 20  # the scene has voxels that only gated samples reached
    # where a voxel has hypotheses, the winner is its colour, not the running mean of the gated samples
    hyp = vol.pool_hn[:n].sum(axis=-1) > 0
    win = np.take_along_axis(vol.pool_hc[:n], vol.pool_hn[:n].argmax(axis=-1)[..., None, None], axis=2)[..., 0, :]
    assert np.array_equal(vol.pool_c[:n][hyp], win[hyp])


def _reference(depth, color, ok, radius, sc, sd):
    """Alg. 7 pixel by pixel in numpy: the ridge fit over each valid pixel's circular window, then the window means of
    (a, b) applied to the pixel's own guide (the kernels' prefix sums must give the same)."""
    h, w = depth.shape
    g = np.concatenate([color.reshape(h, w, 3) / 255.0, depth[..., None].astype(np.float64)], axis=2)
    valid = (depth > 0) & ok.reshape(h, w)
    yy, xx = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    disk = [(dy, dx) for dy, dx in zip(yy.ravel(), xx.ravel()) if dx * dx + dy * dy <= radius * radius]

    def window(v, u):
        return [(v + dy, u + dx) for dy, dx in disk if 0 <= v + dy < h and 0 <= u + dx < w and valid[v + dy, u + dx]]

    ab = np.zeros((h, w, 5))
    for v, u in zip(*np.nonzero(valid)):
        x = np.array([g[p] for p in window(v, u)])
        cov = np.cov(x.T, bias=True)
        reg = cov + np.diag([sc * sc] * 3 + [sd * sd])
        a = np.linalg.solve(reg, cov[:, 3])
        ab[v, u] = np.append(a, x[:, 3].mean() - a @ x.mean(axis=0))
    out = np.zeros((h, w))
    for v, u in zip(*np.nonzero(valid)):
        m = np.mean([ab[p] for p in window(v, u)], axis=0)
        out[v, u] = m[:4] @ g[v, u] + m[4]
    return out


def test_guided_depth_equals_the_per_pixel_fit_and_its_reused_buffers_keep_nothing_between_frames():
    rng = np.random.default_rng(3)
    buffers = {}
    for seed, radius in ((0, 3), (1, 2)):
        depth, color = _images(seed)
        depth, color = depth[:14, 30:52].copy(), color[:14, 30:52].copy()
        depth[rng.random(depth.shape) < 0.1] = 0.0  # holes
        ok = rng.random(depth.shape) > 0.1  # colour samples missing
        e = guided_depth(depth, color, ok.astype(np.uint8), radius=radius, buffers=buffers)
        ref = _reference(depth, color, ok, radius, 0.02, 0.05)
        assert np.count_nonzero(e) == np.count_nonzero((depth > 0) & ok) > 200
        assert np.abs(e - ref).max() < 1e-5  # float32 output of a float64 fit
        assert np.array_equal(e, guided_depth(depth, color, ok.astype(np.uint8), radius=radius))
