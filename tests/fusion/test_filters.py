"""Depth filters: range, bilateral, Kinect V2 shadow (Alg. 5) and veil (eq. 3.19) filters."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from kinfu_cli.core.camera import preset_intrinsics
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.fusion import filters

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
    K = preset_intrinsics("kinect_v1", W, H)
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


def _plane_depth(h=120, w=160):
    """A tilted plane: depth 0.5 m at the left edge rising 0.1 mm per column and 0.05 mm per row."""
    v, u = np.mgrid[0:h, 0:w]
    return (0.5 + 1e-4 * u + 5e-5 * v).astype(np.float32)


def test_fill_gaps_fills_lines_of_no_reading_on_a_surface():
    d = _plane_depth()
    holed = d.copy()
    holed[::5, :] = 0  # whole rows and columns without a reading, as depth registered to a larger image leaves
    holed[:, 3::7] = 0
    holed[40:41, 50:52] = 0  # a 2-pixel run inside a row
    out, n = filters.fill_gaps(holed, max_gap=2)
    inner = np.zeros_like(d, dtype=bool)
    inner[1:-1, 1:-1] = True  # border pixels have a reading on one side only
    assert np.all(out[inner] > 0), "rows, columns, their crossings and the 2-pixel run must be filled"
    assert n == int(np.count_nonzero((holed == 0) & (out > 0)))
    assert np.abs(out - d)[inner].max() < 1e-5  # linear interpolation on a plane is exact
    assert np.array_equal(out[holed > 0], holed[holed > 0])  # readings are never changed


def test_fill_gaps_keeps_edges_blobs_and_can_be_off():
    d = _plane_depth()
    d[:, 80:] += 0.3  # a depth edge at column 80
    holed = d.copy()
    holed[:, 79:81] = 0  # the 2-pixel gap on the edge must not be bridged
    holed[20:30, 20:30] = 0  # a 10 x 10 blob (shadow, glass) is not a thin gap
    holed[60, 40:43] = 0  # 3 pixels: wider than max_gap along the row, but 1 pixel along the column
    out, _ = filters.fill_gaps(holed, max_gap=2)
    assert np.all(out[:, 79:81] == 0)
    assert np.all(out[21:29, 21:29] == 0)
    assert np.all(out[60, 40:43] > 0)
    off, n = filters.fill_gaps(holed, max_gap=0)
    assert n == 0 and np.array_equal(off, holed)
    with pytest.raises(ConfigError, match="max_gap"):
        filters.fill_gaps(holed, max_gap=-1)


def test_fill_gaps_on_real_line_artefacts_removes_unknown_speckles(shared_data):
    """rgbd-tabletop-box depth has a row and column of no reading every few pixels. Fused as they come, every
    voxel whose centre lands on such a line stays unknown inside the observed surface: isolated unknown voxels
    (all 6 neighbours known) that NBV would count as information gain and that break the TSDF normals."""
    import cv2

    from kinfu_cli.fusion.volume import TernaryVolume

    folder = shared_data("rgbd-tabletop-box")
    K = np.loadtxt(folder / "intrinsics.K.txt")
    frames = []
    for i in range(15, 35, 4):
        raw = cv2.imread(str(folder / f"frame-{i:06d}.depth.png"), cv2.IMREAD_UNCHANGED)
        frames.append((filters.range_filter(raw.astype(np.float32) / 1000.0, 0.1, 1.5),
                       np.loadtxt(folder / f"frame-{i:06d}.pose.txt")))

    def isolated_unknown(gap):
        vol = TernaryVolume(size=(0.9, 0.7, 0.9), voxel_size=0.006, origin=(-0.45, -0.35, 0.1), truncation=0.02,
                            min_depth=0.1, max_depth=1.5, color=False)
        for d, T in frames:
            vol.integrate(filters.fill_gaps(d, gap)[0], K, T)
        known = vol.labels() != 0
        iso = ~known[1:-1, 1:-1, 1:-1]
        for ax in range(3):
            for s in (-1, 1):
                iso &= np.roll(known, s, axis=ax)[1:-1, 1:-1, 1:-1]
        return int(iso.sum()), int(known.sum())

    before, known_before = isolated_unknown(0)
    after, known_after = isolated_unknown(2)
    assert (frames[0][0] > 0).mean() < 0.4  # the artefact is there
    assert before > 1000 and after < before / 4, (before, after)
    assert known_after > known_before
