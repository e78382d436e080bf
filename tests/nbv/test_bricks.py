"""The caster's block-by-block label storage and its voxel-level empty-space distances."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import distance_transform_cdt

from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid
from kinfu_cli.nbv.raycast import RayVolume, cast_rays, cast_views
from kinfu_cli.nbv.viewpoints import sphere_viewpoints

from tests.nbv.test_raycast import cluttered_scene


def random_grid(shape=(37, 29, 45), seed=0):
    """Sparse random boxes in empty space; sides not multiples of the block, so edge blocks are padded."""
    rng = np.random.default_rng(seed)
    lab = np.full(shape, EMPTY, np.int8)
    for _ in range(12):
        c = rng.integers(0, np.array(shape) - 2)
        s = rng.integers(1, 5, 3)
        lab[c[0]:c[0] + s[0], c[1]:c[1] + s[1], c[2]:c[2] + s[2]] = rng.choice([OCCUPIED, UNKNOWN])
    lab[:, :, :3] = UNKNOWN  # whole single-label blocks (shared bricks) beside mixed ones
    return TernaryGrid(lab, np.array([0.1, -0.2, 0.0]), 0.02)


def brick_values(vol: RayVolume) -> np.ndarray:
    """What the caster reads for every voxel, gathered back into grid order."""
    B = vol.block
    i, j, k = np.indices(vol.shape).reshape(3, -1)
    idx = vol.brick_of[i // B, j // B, k // B].astype(np.int64) * B ** 3 + ((i % B) * B + j % B) * B + k % B
    return vol.bricks[idx].reshape(vol.shape)


@pytest.mark.parametrize("block,cap", [(8, 4), (4, 3), (16, 6)])
def test_bricks_hold_the_labels_and_capped_chessboard_distances(block, cap):
    g = random_grid()
    vol = RayVolume.from_grid(g, block=block, fine_cap=cap)
    got = brick_values(vol)
    non_empty = g.labels != EMPTY
    assert np.array_equal(got[non_empty], g.labels[non_empty])
    # EMPTY voxels read as -d: d = chessboard distance to the nearest non-empty voxel, capped, in mixed blocks
    # (voxels outside the volume count as EMPTY); all-EMPTY blocks share one brick of -1 (no voxel-level skip)
    dist = np.minimum(distance_transform_cdt(~non_empty, metric="chessboard"), cap)
    B = block
    kinds = np.zeros(vol.brick_of.shape, bool)
    kinds[vol.brick_of >= 3] = True
    mixed = kinds[np.arange(g.labels.shape[0])[:, None, None] // B, np.arange(g.labels.shape[1])[None, :, None] // B,
                  np.arange(g.labels.shape[2])[None, None, :] // B]
    sel = mixed & ~non_empty
    assert sel.sum() > 1000
    assert np.array_equal(-got[sel], dist[sel])
    assert np.all(got[~mixed & ~non_empty] == -1)
    # only blocks holding two different labels own a brick
    assert len(vol.bricks) == (3 + int((vol.brick_of >= 3).sum())) * B ** 3


def test_voxel_level_skips_give_the_exact_traversal_for_every_block_size():
    g = random_grid(seed=5)
    plain = RayVolume.from_grid(g, block=1)
    plain.block_dist[:] = 0  # no skipping: one voxel at a time
    rng = np.random.default_rng(1)
    o = np.array([-0.3, 0.9, 0.5])
    dirs = rng.normal(size=(3000, 3)) + [1.5, -1.2, 0.0]
    b = cast_rays(plain, o, dirs, center=[0.4, 0.2, 0.4], radius=0.3, through=True)
    for block, cap in ((2, 2), (4, 4), (8, 4), (8, 8), (16, 6)):
        a = cast_rays(RayVolume.from_grid(g, block=block, fine_cap=cap), o, dirs, center=[0.4, 0.2, 0.4],
                      radius=0.3, through=True)
        assert np.array_equal(a.cls, b.cls)
        assert np.allclose(a.terms, b.terms)
        assert np.allclose(a.t[np.isfinite(a.t)], b.t[np.isfinite(b.t)])


def test_view_sums_do_not_depend_on_block_size_and_skips_are_used():
    g, poi = cluttered_scene(seed=3)
    # a POI off the voxel faces: with it on a face these axis-aligned views send rays exactly along voxel
    # edges, and a skip may leave such a ray on either side of a voxel it only touches
    poi = poi + [0.0037, -0.0026, 0.0015]
    cam = CameraModel(110.0, 110.0, 63.5, 47.5, 128, 96, min_range=0.3, max_range=3.0)
    poses = sphere_viewpoints(poi, 0.8, lon_step=90, lat_step=30, roll_step=90)
    runs = [cast_views(RayVolume.from_grid(g, block=b, fine_cap=c), poses, cam, poi, 0.2, through=True)
            for b, c in ((4, 4), (8, 4), (16, 6), (8, 1))]
    for r in runs[1:]:
        assert np.array_equal(runs[0].counts, r.counts) and np.array_equal(runs[0].rays, r.rays)
        assert np.allclose(runs[0].terms, r.terms, rtol=1e-12, atol=0)
    r = runs[1]
    assert r.counts.sum() == r.rays.sum() and r.terms[:, 0].min() > 100
    # each ray from its group's free start: the voxel-level skips replace most single-voxel steps near surfaces
    walk, plain = (cast_views(RayVolume.from_grid(g, block=8, fine_cap=c), poses, cam, poi, 0.2, through=True,
                              march=False) for c in (4, 1))
    assert np.array_equal(walk.counts, r.counts) and np.allclose(walk.terms, r.terms, rtol=1e-12, atol=0)
    assert walk.fine_steps > 0 and plain.fine_steps == 0
    assert walk.voxel_steps + walk.fine_steps < 0.8 * plain.voxel_steps
    # up to the first hit, the bundles' march takes more than half of the rays' empty-space skips
    vol = RayVolume.from_grid(g)
    a, b = (cast_views(vol, poses, cam, poi, 0.2, march=m) for m in (True, False))
    assert np.array_equal(a.counts, b.counts) and np.allclose(a.terms, b.terms, rtol=1e-12, atol=0)
    assert a.block_steps + a.fine_steps < 0.5 * (b.block_steps + b.fine_steps)


def test_bundle_starts_lie_before_the_first_hit_of_each_of_their_rays():
    """Every ray of a bundle starts at the bundle's march result: nothing non-empty may lie before it."""
    from kinfu_cli.nbv import raycast

    g, poi = cluttered_scene(seed=3)
    vol = RayVolume.from_grid(g)
    cam = CameraModel(220.0, 220.0, 127.5, 95.5, 256, 192, min_range=0.3, max_range=3.0)
    poses = sphere_viewpoints(poi, 0.8, lon_step=90, lat_step=45, roll_step=180)
    seen = {}

    def spy(*args):
        seen["args"] = args
        return cast_lattice(*args)

    cast_lattice = raycast._cast_lattice
    raycast._cast_lattice = spy
    try:
        for group in raycast.group_views(poses):
            for march in (True, False):
                raycast.cast_views(vol, poses[group], cam, poi, 0.2, march=march)
                a = seen["args"]
                tdir, R0, t0, tcone, coff, cstart = a[9], a[14][0], a[15][0], a[16], a[17], a[18]
                start = cstart[coff[0] + tcone]
                hit = cast_rays(vol, t0, tdir @ R0.T, center=poi, radius=0.2).t
                assert np.all(hit >= start)
                f = np.isfinite(hit)
                seen.setdefault(march, []).append(np.median(hit[f] - start[f]) / vol.voxel_size)
    finally:
        raycast._cast_lattice = cast_lattice
    # not trivial: a typical ray starts a few voxels from its hit, much nearer than its group's free start
    assert np.median(seen[True]) < 4 and np.median(seen[True]) < 0.5 * np.median(seen[False])


def test_block_must_be_a_power_of_two():
    with pytest.raises(ConfigError, match="power of two") as e:
        RayVolume.from_grid(random_grid(), block=6)
    assert e.value.parameter == "block"


def test_free_start_lies_before_the_first_hit_of_every_ray_in_the_cone():
    """The caster starts a group's rays at `_free_start`: every ray towards S must meet nothing before it."""
    from kinfu_cli.nbv.raycast import _free_start

    g, poi = cluttered_scene(seed=3)
    vol = RayVolume.from_grid(g)
    poses = sphere_viewpoints(poi, 0.8, lon_step=45, lat_step=30, roll_step=90)
    sensors = np.unique(poses[:, :3, 3].round(9), axis=0)
    r_ext = 0.2 + vol.voxel_size * np.sqrt(3) / 2
    tf = _free_start(vol, sensors, poi, r_ext, np.ones(len(sensors), bool))
    assert (tf > 0.1).mean() > 0.5 and tf.max() > 0.3  # not trivial: most rays skip part of their way
    rng = np.random.default_rng(0)
    for p, t in zip(sensors, tf):
        a = (poi - p) / np.linalg.norm(poi - p)
        # directions filling the cone towards S (half-angle asin(r_ext / distance)), its rim included
        u = np.cross(a, [0.3, 0.5, 0.8])
        u /= np.linalg.norm(u)
        w = np.cross(a, u)
        ang = np.arcsin(r_ext / np.linalg.norm(poi - p)) * np.sqrt(rng.uniform(0, 1, 2000))
        ang[:200] = np.arcsin(r_ext / np.linalg.norm(poi - p))
        phi = rng.uniform(0, 2 * np.pi, 2000)
        d = (np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w))
        hit = cast_rays(vol, p, d, center=poi, radius=0.2).t
        assert hit.min() >= t
    # a sensor inside a block that is not free starts at once
    b = np.argwhere(vol.block_dist == 0)[0]
    inside = vol.origin + (b + 0.5) * vol.block * vol.voxel_size
    assert _free_start(vol, inside[None], poi, r_ext, np.ones(1, bool))[0] == 0.0
