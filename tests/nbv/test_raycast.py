"""Ray casting through the ternary map: exact known answers and agreement with the reference marcher."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.nbv.raycast import (CLS_EMPTY_EXIT, CLS_OCCUPIED, CLS_UNKNOWN, RayVolume, cast_rays, cast_views,
                                   group_views, knowledge_map)
from kinfu_cli.nbv.ranking import forget_around
from kinfu_cli.nbv.reference import reference_views
from kinfu_cli.core.poses import look_at
from kinfu_cli.nbv.viewpoints import sphere_viewpoints

CAM = CameraModel(60.0, 60.0, 39.5, 29.5, 80, 60, min_range=0.2, max_range=4.0)


def empty_grid(n=64, vs=0.02):
    return TernaryGrid(np.full((n, n, n), EMPTY, np.int8), np.zeros(3), vs)


def ray_box_hits(o, dirs, lo, hi):
    """Analytic slab test: does each ray (o + t d, t > 0) cross the box [lo, hi] with positive length?"""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - o) / dirs
        t2 = (hi - o) / dirs
    tn = np.nanmax(np.minimum(t1, t2), axis=1)
    tf = np.nanmin(np.maximum(t1, t2), axis=1)
    return (tf > np.maximum(tn, 0) + 1e-9)


def test_single_unknown_box_gain_equals_analytic_ray_count():
    g = empty_grid()
    g.labels[28:36, 30:34, 20:30] = UNKNOWN  # box [0.56,0.72] x [0.60,0.68] x [0.40,0.60]
    lo, hi = np.array([0.56, 0.60, 0.40]), np.array([0.72, 0.68, 0.60])
    center = (lo + hi) / 2
    vol = RayVolume.from_grid(g)
    for eye in ([0.1, 0.2, 0.9], [1.2, 0.64, 0.5], [0.64, 0.64, 1.2]):
        T = look_at(eye, center + [0.013, -0.007, 0.004])
        km = knowledge_map(vol, T, CAM, center=center, radius=0.5)
        dirs = CAM.pixel_rays() @ T[:3, :3].T
        expect = ray_box_hits(np.asarray(eye, float), dirs, lo, hi)
        assert expect.sum() > 50
        assert np.array_equal(km.cls == CLS_UNKNOWN, expect)
        assert np.all(km.cls[~expect] == CLS_EMPTY_EXIT)
        assert km.terms[:, 0].sum() == expect.sum()
        # the batched path (restricted to rays that can reach S) gives the same gain
        vr = cast_views(vol, T[None], CAM, center, 0.5)
        assert vr.terms[0, 0] == expect.sum()
        assert vr.counts[0, 0] == expect.sum()


def test_ray_stops_at_first_non_empty_voxel_and_reports_distance():
    g = empty_grid()
    g.labels[40, :, :] = OCCUPIED  # wall at x in [0.80, 0.82)
    g.labels[20, :, :] = UNKNOWN  # unknown sheet at x in [0.40, 0.42)
    vol = RayVolume.from_grid(g)
    o = np.array([0.05, 0.5, 0.5])
    r = cast_rays(vol, o, np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0]]), center=[0.41, 0.5, 0.5],
                  radius=0.1)
    assert list(r.cls) == [CLS_UNKNOWN, CLS_EMPTY_EXIT, CLS_EMPTY_EXIT]
    assert r.t[0] == pytest.approx(0.35)
    assert r.terms[0, 0] == 1.0 and r.terms[0, 1] == pytest.approx(1 / 0.35 ** 2)
    # walking on through unknown: one unknown voxel in S = 1 bit; the wall is not right behind it: no rear
    r2 = cast_rays(vol, o, np.array([[1.0, 0, 0]]), center=[0.41, 0.5, 0.5], radius=0.1, through=True)
    assert r2.terms[0, 3] == pytest.approx(1.0) and r2.terms[0, 2] == 0.0
    # two unknown voxels right in front of the wall: entropy 1 + 1/2 bits, and the wall's rear side
    g.labels[20, :, :] = EMPTY
    g.labels[38:40, :, :] = UNKNOWN
    r3 = cast_rays(RayVolume.from_grid(g), o, np.array([[1.0, 0, 0]]), center=[0.79, 0.5, 0.5], radius=0.1,
                   through=True)
    assert r3.cls[0] == CLS_UNKNOWN and r3.terms[0, 2] == 1.0 and r3.terms[0, 3] == pytest.approx(1.5)
    # without the unknown voxels: a plain occupied hit, no gain of any kind
    g.labels[38:40, :, :] = EMPTY
    r4 = cast_rays(RayVolume.from_grid(g), o, np.array([[1.0, 0, 0]]), center=[0.79, 0.5, 0.5], radius=0.1,
                   through=True)
    assert r4.cls[0] == CLS_OCCUPIED and not r4.terms[0].any()


def test_min_range_hits_do_not_count_and_max_range_ends_rays():
    g = empty_grid()
    g.labels[10:, :, :] = UNKNOWN  # from x = 0.20 on
    vol = RayVolume.from_grid(g)
    o, d = np.array([0.05, 0.5, 0.5]), np.array([[1.0, 0, 0]])
    near = cast_rays(vol, o, d, min_range=0.5, center=[0.3, 0.5, 0.5], radius=0.2)
    assert near.cls[0] == CLS_UNKNOWN and near.terms[0, 0] == 0.0  # hit at 0.15 m < min range
    short = cast_rays(vol, o, d, max_range=0.1, center=[0.3, 0.5, 0.5], radius=0.2)
    assert short.cls[0] == CLS_EMPTY_EXIT


def test_empty_block_skipping_matches_plain_traversal():
    rng = np.random.default_rng(3)
    lab = np.full((50, 45, 40), EMPTY, np.int8)
    for _ in range(25):
        c = rng.integers(0, 40, 3)
        s = rng.integers(1, 6, 3)
        lab[c[0]:c[0] + s[0], c[1]:c[1] + s[1], c[2]:c[2] + s[2]] = rng.choice([OCCUPIED, UNKNOWN])
    g = TernaryGrid(lab, [-0.3, 0.1, 0.0], 0.015)
    fast = RayVolume.from_grid(g, block=8)
    plain = RayVolume.from_grid(g, block=1)
    plain.block_dist[:] = 0  # no skipping at all
    o = np.array([-0.5, 0.05, 0.7])
    dirs = rng.normal(size=(4000, 3)) + [1.5, 1.0, -1.0]
    a = cast_rays(fast, o, dirs, center=[0.0, 0.4, 0.3], radius=0.25, through=True)
    b = cast_rays(plain, o, dirs, center=[0.0, 0.4, 0.3], radius=0.25, through=True)
    assert np.array_equal(a.cls, b.cls)
    assert np.allclose(a.terms, b.terms)
    assert np.allclose(a.t[np.isfinite(a.t)], b.t[np.isfinite(b.t)])


def cluttered_scene(n=96, vs=0.0125, seed=1):
    """Tabletop-like grid: table top, random occupied / unknown boxes, and the POI sphere cleared."""
    rng = np.random.default_rng(seed)
    lab = np.full((n, n, n), EMPTY, np.int8)
    lab[:, :, :30] = UNKNOWN
    lab[:, :, 30] = OCCUPIED
    for _ in range(40):
        c = rng.integers(5, n - 10, 3)
        c[2] = rng.integers(31, 60)
        s = rng.integers(2, 9, 3)
        lab[c[0]:c[0] + s[0], c[1]:c[1] + s[1], c[2]:c[2] + s[2]] = rng.choice([OCCUPIED, UNKNOWN])
    g = TernaryGrid(lab, np.zeros(3), vs)
    poi = np.array([0.6, 0.6, 0.45])
    forget_around(g, poi, 0.2)
    return g, poi


@pytest.mark.parametrize("through", [False, True])
def test_fast_gains_match_reference_marcher(through):
    g, poi = cluttered_scene()
    vol = RayVolume.from_grid(g)
    cam = CameraModel(110.0, 110.0, 63.5, 47.5, 128, 96, min_range=0.3, max_range=3.0)
    poses = sphere_viewpoints(poi, 0.8, lon_step=90, lat_step=30, roll_step=45)[::3]  # 32 views, mixed rolls
    ref_counts, ref_terms = reference_views(vol, poses, cam, poi, 0.2, through=through)
    exact = cast_views(vol, poses, cam, poi, 0.2, through=through, share_rolls=False, restrict=False)
    shared = cast_views(vol, poses, cam, poi, 0.2, through=through)
    ref = ref_terms[:, 0]
    assert ref.min() > 500
    # exact traversal vs half-voxel steps: they differ only on rays grazing voxel corners, a band along
    # silhouettes whose share shrinks with resolution (here S is only 16 voxels across; < 1 % at 512^3)
    assert np.max(np.abs(exact.terms[:, 0] - ref) / ref) < 0.03
    assert np.mean(np.abs(exact.terms[:, 0] - ref) / ref) < 0.01
    # shared roll rays round to the nearest pixel of the first roll: small extra differences
    assert np.max(np.abs(shared.terms[:, 0] - ref) / ref) < 0.035
    assert np.mean(np.abs(shared.terms[:, 0] - ref) / ref) < 0.015
    # full-image knowledge-map counts agree too (all pixels)
    assert np.array_equal(exact.counts.sum(axis=1), ref_counts.sum(axis=1))
    assert np.max(np.abs(exact.counts - ref_counts) / ref_counts.sum(axis=1, keepdims=True)) < 0.02
    if through:
        e, r = exact.terms[:, 3], ref_terms[:, 3]
        assert np.max(np.abs(e - r) / r) < 0.03
        # distance weighting: same hits, 1/t^2 with t from voxel entry (exact) vs sample (reference)
        assert np.max(np.abs(exact.terms[:, 1] - ref_terms[:, 1]) / ref_terms[:, 1]) < 0.03


def test_restricting_rays_to_the_sphere_keeps_every_gain_ray():
    g, poi = cluttered_scene(seed=4)
    # off the voxel faces: these axis-aligned views would otherwise send rays exactly through voxel
    # corners, where a walk started elsewhere (each bundle's march) may pass on either side
    poi = poi + [0.0037, -0.0026, 0.0015]
    vol = RayVolume.from_grid(g)
    cam = CameraModel(110.0, 110.0, 63.5, 47.5, 128, 96, min_range=0.3, max_range=3.0)
    poses = sphere_viewpoints(poi, 0.8, lon_step=60, lat_step=45, roll_step=180)
    full = cast_views(vol, poses, cam, poi, 0.2, through=True, share_rolls=False, restrict=False)
    part = cast_views(vol, poses, cam, poi, 0.2, through=True, share_rolls=False, restrict=True)
    assert np.allclose(full.terms, part.terms)
    assert part.rays_cast < 0.6 * full.rays_cast


def test_shared_rolls_are_exact_for_half_turns_of_a_centred_camera():
    g, poi = cluttered_scene(seed=2)
    vol = RayVolume.from_grid(g)
    cam = CameraModel(110.0, 110.0, 63.5, 47.5, 128, 96, min_range=0.3, max_range=3.0)  # centred principal point
    poses = sphere_viewpoints(poi, 0.8, lon_step=120, lat_max=60, lat_step=30, roll_step=180)  # no pole
    a = cast_views(vol, poses, cam, poi, 0.2, share_rolls=True)
    b = cast_views(vol, poses, cam, poi, 0.2, share_rolls=False)
    assert np.array_equal(a.counts, b.counts) and np.allclose(a.terms, b.terms)
    assert a.rays_cast < 0.6 * b.rays_cast


def test_optimistic_rays_pass_unknown_outside_the_region_and_match_the_reference():
    g = empty_grid()
    g.labels[10:14, :, :] = UNKNOWN  # an unseen slab between the sensor and the region
    g.labels[28:36, 28:36, 28:36] = UNKNOWN  # the region's unknown box (0.16 m)
    vol = RayVolume.from_grid(g)
    center = np.array([0.64, 0.64, 0.64])
    o = np.array([0.05, 0.64, 0.64])
    d = np.array([[1.0, 0.0, 0.0]])
    paper = cast_rays(vol, o, d, center=center, radius=0.1)
    opt = cast_rays(vol, o, d, center=center, radius=0.1, optimistic=True)
    assert paper.cls[0] == CLS_UNKNOWN and paper.terms[0, 0] == 0.0  # stopped by the slab
    assert opt.cls[0] == CLS_UNKNOWN and opt.terms[0, 0] == 1.0 and opt.t[0] == pytest.approx(0.51)
    T = look_at([0.05, 0.6, 0.7], center)
    ref_c, ref_t = reference_views(vol, T[None], CAM, center, 0.15, optimistic=True)
    fast = cast_views(vol, T[None], CAM, center, 0.15, optimistic=True)
    assert ref_t[0, 0] > 200 and abs(fast.terms[0, 0] - ref_t[0, 0]) <= 0.03 * ref_t[0, 0]
    assert cast_views(vol, T[None], CAM, center, 0.15).terms[0, 0] == 0  # the paper's rule: the slab hides it
    # the distance field that also skips far unknown blocks gives exactly the same rays
    skip = cast_views(vol.optimistic_for(center, 0.15), T[None], CAM, center, 0.15, optimistic=True, through=True)
    plain = cast_views(vol, T[None], CAM, center, 0.15, optimistic=True, through=True)
    assert np.array_equal(skip.counts, plain.counts) and np.allclose(skip.terms, plain.terms)


def test_reference_converges_to_exact_traversal_as_its_step_shrinks():
    """The residual gain difference is the reference's fixed step skipping voxel corners: at 1/8 voxel the
    reference agrees with exact traversal much better than at the paper's half voxel (a residual ~0.2 % stays:
    rays that graze the range limits)."""
    g, poi = cluttered_scene()
    vol = RayVolume.from_grid(g)
    cam = CameraModel(110.0, 110.0, 63.5, 47.5, 128, 96, min_range=0.3, max_range=3.0)
    poses = sphere_viewpoints(poi, 0.8, lon_step=90, lat_step=30, roll_step=45)[::8]
    exact = cast_views(vol, poses, cam, poi, 0.2, share_rolls=False, restrict=False).terms[:, 0]
    err = {}
    for step in (0.5, 0.125, 1 / 32):
        ref = reference_views(vol, poses, cam, poi, 0.2, step=step)[1][:, 0]
        err[step] = np.mean(np.abs(exact - ref) / ref)
    assert err[0.5] > err[0.125] > err[1 / 32]
    assert err[1 / 32] < 0.003
    assert err[1 / 32] < 0.4 * err[0.5]


def test_sphere_positions_share_one_template_and_match_casting_each_position_alone():
    """All positions of the viewing sphere see S alike relative to their sensor, so they share one lattice
    template (plus one for the pole, where all longitudes meet); the sums equal casting position by position.
    The principal point is off the pixel grid's symmetry so no pixel ties between two lattice rays."""
    g, poi = cluttered_scene(seed=5)
    vol = RayVolume.from_grid(g)
    cam = CameraModel(110.0, 110.0, 63.3, 47.2, 128, 96, min_range=0.3, max_range=3.0)
    poses = sphere_viewpoints(poi, 0.8, lon_step=90, lat_step=30, roll_step=45)
    shared = cast_views(vol, poses, cam, poi, 0.2, through=True)
    assert shared.templates == 2
    alone_counts = np.zeros_like(shared.counts)
    alone_terms = np.zeros_like(shared.terms)
    built = 0
    groups = group_views(poses)  # the rolls of one position (all longitudes' rolls at the pole)
    for idx in groups:
        r = cast_views(vol, poses[idx], cam, poi, 0.2, through=True)
        alone_counts[idx], alone_terms[idx] = r.counts, r.terms
        built += r.templates
    assert built == len(groups) == 3 * 4 + 1
    assert np.array_equal(shared.counts, alone_counts)
    assert np.allclose(shared.terms, alone_terms, rtol=1e-12, atol=1e-9)
    assert shared.rays_cast > 0 and shared.voxel_steps > 0 and shared.block_steps > 0
