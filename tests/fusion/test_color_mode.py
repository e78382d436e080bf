"""The colour mode filter (fuse --color mode): hypotheses and counts, winner takes all, the volume file, the
command line, and the issue 12 measurement: sharper colour borders than the running mean under auto-gain and
colour-depth misregistration."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.fusion.color_mode import mode_update, mode_winners
from kinfu_cli.fusion.volume import TernaryVolume, load_volume
from kinfu_cli.sim.color_truth import border_color_errors, surface_truth
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import primitive_tabletop_scene
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

RED, GREEN, BLUE = (200, 30, 30), (30, 180, 40), (20, 40, 210)


def _pools(m=3):
    return np.zeros((1, 512, m, 3), np.uint8), np.zeros((1, 512, m), np.uint8), np.zeros((1, 512, 3), np.uint8)


def _feed(hc, hn, samples, k=0, thr=40.0):
    for c in samples:
        mode_update(hc, hn, 0, k, np.uint8(c[0]), np.uint8(c[1]), np.uint8(c[2]), np.float32(thr * thr))


def test_most_seen_colour_wins_and_is_not_blended():
    hc, hn, pc = _pools()
    rng = np.random.default_rng(0)
    samples = [RED] * 7 + [GREEN] * 5
    samples = [tuple(np.clip(np.array(samples[i]) + rng.integers(-4, 5, 3), 0, 255)) for i in rng.permutation(12)]
    _feed(hc, hn, samples)
    assert sorted(hn[0, 0][hn[0, 0] > 0].tolist()) == [5, 7]
    mode_winners(hc, hn, pc, 1)
    assert np.abs(pc[0, 0].astype(int) - RED).max() <= 4  # the red mode, not a red-green mix
    assert not pc[0, 1:].any()  # voxels without hypotheses keep their colour


def test_a_new_colour_replaces_the_least_seen_hypothesis():
    hc, hn, _ = _pools(m=2)
    _feed(hc, hn, [RED] * 3 + [GREEN] + [BLUE])
    assert {tuple(hc[0, 0, m]) for m in range(2)} == {RED, BLUE}
    assert sorted(hn[0, 0].tolist()) == [1, 3]


def test_within_the_threshold_one_hypothesis_follows_the_samples():
    hc, hn, _ = _pools()
    _feed(hc, hn, [(100, 100, 100), (110, 100, 100), (90, 100, 100)] * 4, thr=40.0)
    assert np.count_nonzero(hn[0, 0]) == 1 and hn[0, 0].max() == 12
    assert abs(int(hc[0, 0, np.argmax(hn[0, 0]), 0]) - 100) <= 6
    hc, hn, _ = _pools()
    _feed(hc, hn, [(100, 100, 100), (160, 100, 100)], thr=40.0)
    assert np.count_nonzero(hn[0, 0]) == 2


def test_counts_saturate_keeping_their_ratio():
    hc, hn, pc = _pools()
    _feed(hc, hn, ([RED] * 3 + [GREEN]) * 150)  # 450 red, 150 green: past uint8 counts
    n = np.sort(hn[0, 0][hn[0, 0] > 0])
    assert n.max() < 255 and 2.0 < n[1] / n[0] < 4.5
    mode_winners(hc, hn, pc, 1)
    assert tuple(pc[0, 0]) == RED


def test_close_hypotheses_merge():
    """Eq. 4.10 (sigma = T / 5): a rare hypothesis near a frequent one is folded into it, a far one is kept."""
    for other, merged in ((112, True), (130, False)):
        hc, hn, _ = _pools()
        hc[0, 0, 0] = (100, 100, 100)
        hc[0, 0, 1] = (other, 100, 100)
        hn[0, 0, :2] = (20, 1)
        _feed(hc, hn, [(100, 100, 100)])
        assert (np.count_nonzero(hn[0, 0]) == 1) == merged
        assert hn[0, 0].sum() == 22 and hn[0, 0, 0] == (22 if merged else 21)


# ---- volumes -------------------------------------------------------------------------------------------

W, H = 240, 180


def _sequence(seed, n, effects=True):
    scene = primitive_tabletop_scene(seed=seed)
    K = kinect_v1_intrinsics(W, H)
    fx = dict(gain_jitter=0.15, white_balance_jitter=0.04, misregistration=(1.5, -1.0, 0.3)) if effects else {}
    sensor = DepthSensor(K, W, H, noise=True, seed=seed, **fx)
    poses = orbit_poses(n, radius=0.85, height=1.3, target=(0.0, 0.0, 0.75), start_deg=40.0 * seed)
    frames = [(*sensor.render(scene, T), K, T) for T in poses]
    return scene, frames, np.mean([T[:3, 3] for T in poses], axis=0)


def _volume(mode, vs=0.004):
    return TernaryVolume(size=(1.28, 0.8, 0.4), voxel_size=vs, origin=(-0.64, -0.4, 0.6), truncation=4 * vs,
                         min_depth=0.2, max_depth=2.0, color_mode=mode)


def _fuse(vol, frames):
    for d, c, K, T in frames:
        vol.integrate(d, K, T, c)
    return vol


@pytest.fixture(scope="module")
def small():
    return _sequence(11, 8, effects=True)


def test_mode_volume_round_trips_and_continues_like_one_run(small, tmp_path):
    _, frames, _ = small
    one = _fuse(_volume("mode", 0.008), frames)
    part = _fuse(_volume("mode", 0.008), frames[:4])
    part.save(tmp_path / "volume.npz")
    back = load_volume(tmp_path / "volume.npz")
    assert back.color_mode == "mode" and np.array_equal(back.pool_hn[:back.n_used], part.pool_hn[:part.n_used])
    cont = _fuse(back, frames[4:])
    for x, y in zip(one.tsdf_weights(color=True), cont.tsdf_weights(color=True)):
        assert np.array_equal(x, y)
    # the exported colour is the winning hypothesis of every voxel that has one
    n = one.n_used
    win = np.take_along_axis(one.pool_hc[:n], np.argmax(one.pool_hn[:n], axis=2)[..., None, None], 2)[:, :, 0]
    has = one.pool_hn[:n].max(axis=2) > 0
    assert has.sum() > 1000 and np.array_equal(one.pool_c[:n][has], win[has])
    # a mean volume has no hypotheses and no extra memory
    mean = _fuse(_volume("mean", 0.008), frames[:2])
    assert mean.pool_hc.size == 0 and mean.meta()["color_mode"] == "mean"


@pytest.mark.parametrize("mode", ["mean", "mode"])
def test_voxel_colors_read_what_the_dense_box_holds(small, mode):
    """voxel_colors (segmentation reads colour at its vertices only) = the dense colour box at the same voxels,
    the mode's winners included (read without an explicit sync) and black where no block is stored."""
    _, frames, _ = small
    vol = _fuse(_volume(mode, 0.008), frames)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, np.array(vol.shape), (20000, 3))
    got = vol.voxel_colors(idx)  # first: it must bring the mode's winners into the pool itself
    dense = vol.tsdf_weights(color=True)[2]
    assert got.dtype == np.uint8 and np.array_equal(got, dense[idx[:, 0], idx[:, 1], idx[:, 2]])
    stored = vol.block_idx[tuple((idx // 8).T)] >= 0
    assert stored.any() and (~stored).any() and not got[~stored].any() and got[stored].any()
    assert vol.voxel_colors(np.zeros((0, 3), np.int64)).shape == (0, 3)


def test_mode_keeps_surface_colours_where_there_is_no_edge():
    """Without photometric effects the mode filter's colours are as close to the truth as the mean's."""
    scene, frames, vp = _sequence(12, 6, effects=False)
    errs = {}
    for mode in ("mean", "mode"):
        vol = _fuse(_volume(mode, 0.006), frames)
        lo, hi = vol.surface_block_box()
        _, tw, tc = vol.tsdf_weights(lo, hi, color=True)
        errs[mode] = border_color_errors(tc, tw, vol.origin + lo * vol.voxel_size, vol.voxel_size, scene, vp)
    assert errs["mode"].elsewhere.size > 5000
    assert np.median(errs["mode"].elsewhere) <= np.median(errs["mean"].elsewhere) + 1.0


def test_truth_is_the_noise_free_camera_colour():
    scene = primitive_tabletop_scene(seed=3)
    K = kinect_v1_intrinsics(W, H)
    T = orbit_poses(1, radius=0.8, height=1.3, target=(0.0, 0.0, 0.75))[0]
    frame = DepthSensor(K, W, H, noise=False).render_frame(scene, T)
    ok = frame.depth > 0
    v, u = np.nonzero(ok)
    d = frame.depth[ok]
    pts = np.stack([(u - K[0, 2]) / K[0, 0] * d, (v - K[1, 2]) / K[1, 1] * d, d], 1) @ T[:3, :3].T + T[:3, 3]
    colour, labels, dist = surface_truth(scene, pts, T[:3, 3])
    assert np.percentile(dist, 99) < 1e-4
    same = labels == frame.labels[ok]
    assert same.mean() > 0.99
    assert np.median(np.abs(colour[same] - frame.color[ok][same]).max(axis=1)) <= 1.0


@pytest.mark.slow
def test_mode_sharpens_borders_under_auto_gain_and_misregistration():
    """Issue 12's measurement on a sequence not used to choose M and T (seed 7; those were 101-103)."""
    scene, frames, vp = _sequence(7, 30)
    res = {}
    for mode in ("mean", "mode"):
        vol = _fuse(_volume(mode), frames)
        lo, hi = vol.surface_block_box()
        _, tw, tc = vol.tsdf_weights(lo, hi, color=True)
        res[mode] = border_color_errors(tc, tw, vol.origin + lo * vol.voxel_size, vol.voxel_size, scene, vp)
    mean, mode = res["mean"], res["mode"]
    assert mean.border.size > 1000 and mode.border.size > 1000
    # border voxels keep one side's colour: a lower median error and less blur than the running mean (measured
    # 27.7 vs 37.1 and 21.9 vs 29.6; the mean error is about equal, 50 vs 48: a concave corner's voxel sees both
    # surfaces, and picking the other one's colour costs more than a blend)
    assert np.median(mode.border) < 0.8 * np.median(mean.border)
    assert mode.border_blur.mean() < 0.8 * mean.border_blur.mean()
    # and elsewhere no worse than the mean beyond noise (19.9 vs 19.0)
    assert mode.elsewhere.mean() <= mean.elsewhere.mean() + 1.5


# ---- command line --------------------------------------------------------------------------------------

FAST = ["--voxel-size", "0.02", "--size", "2.0", "--quiet"]


@pytest.fixture(scope="module")
def mode_run(sample_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("fuse_mode") / "out"
    res = CliRunner().invoke(cli, ["fuse", str(sample_dir / "recording.mcap"), "-o", str(out), *FAST,
                                   "--color", "mode", "--every", "4"])
    assert res.exit_code == 0, res.output
    return out


def test_fuse_color_mode_writes_a_mode_volume(mode_run):
    report = json.loads((mode_run / "report.json").read_text())
    assert report["grid"]["color_mode"] == "mode"
    vol = load_volume(mode_run / "volume.npz")
    assert vol.color_mode == "mode" and vol.meta()["color_hypotheses"] == vol.pool_hn.shape[2]
    _, tw, tc = vol.tsdf_weights(color=True)
    assert np.count_nonzero(tc.max(axis=-1)) > 1000  # the winners are in the colour the mesh and segment read


def test_fuse_color_errors_are_one_line(mode_run, sample_dir, tmp_path):
    rec = str(sample_dir / "recording.mcap")
    res = CliRunner().invoke(cli, ["fuse", rec, "-o", str(tmp_path / "a"), *FAST, "--color", "mode", "--no-color"])
    one_line_error(res, "--color")
    mean_out = tmp_path / "mean"
    res = CliRunner().invoke(cli, ["fuse", rec, "-o", str(mean_out), *FAST, "--every", "8"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(cli, ["fuse", rec, "-o", str(tmp_path / "b"), *FAST, "--every", "8", "--init",
                                   str(mean_out / "volume.npz"), "--color", "mode"])
    one_line_error(res, "--color", "mean")
    # without --color, --init continues in the volume's own mode
    res = CliRunner().invoke(cli, ["fuse", rec, "-o", str(tmp_path / "c"), *FAST, "--every", "8", "--init",
                                   str(mode_run / "volume.npz")])
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "c" / "report.json").read_text())["grid"]["color_mode"] == "mode"


def test_a_foreign_colour_mode_in_volume_npz_is_a_volume_error(small, tmp_path):
    from kinfu_cli.core.errors import VolumeError
    from kinfu_cli.core.volume_file import read_volume_file, write_volume_file

    vol = _fuse(_volume("mode", 0.008), small[1][:2])
    vol.save(tmp_path / "v.npz")
    meta, arrays = read_volume_file(tmp_path / "v.npz")
    write_volume_file(tmp_path / "bad.npz", {**meta, "color_mode": "median"}, arrays)
    with pytest.raises(VolumeError, match="color_mode"):
        load_volume(tmp_path / "bad.npz")
    write_volume_file(tmp_path / "lost.npz", meta, {k: v for k, v in arrays.items() if k != "pool_hn"})
    with pytest.raises(VolumeError, match="hypothesis"):
        load_volume(tmp_path / "lost.npz")
