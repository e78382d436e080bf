"""The simulated Kinect: exact depth without noise, noise statistics of the Nguyen et al. model, dropouts."""

import numpy as np
import open3d as o3d
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.scene import make_tabletop_scene
from kinfu_cli.sim.sensor import DepthSensor, ideal_depth, kinect_v1_intrinsics, nguyen_axial_sigma

W, H = 160, 120


def _plane(z0=0.0, size=20.0):
    m = o3d.geometry.TriangleMesh.create_box(size, size, 0.01)
    m.translate((-size / 2, -size / 2, z0 - 0.01))
    return m


def _down(height, tilt_deg=0.0):
    """Camera `height` above the plane z=0 looking down, tilted about its x axis."""
    a = np.deg2rad(tilt_deg)
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0]) @ Rx   # optical z points down (-z world)
    T[:3, 3] = (0.0, 0.0, height)
    return T


def test_intrinsics_scale_from_kinect_v1():
    K = kinect_v1_intrinsics(640, 480)
    assert K[0, 0] == K[1, 1] == 585.0 and (K[0, 2], K[1, 2]) == (319.5, 239.5)
    assert np.allclose(kinect_v1_intrinsics(320, 240)[:2, :2], np.diag([292.5, 292.5]))


@pytest.mark.parametrize("tilt", [0.0, 25.0])
def test_depth_of_a_known_plane_is_exact_without_noise(tilt):
    K = kinect_v1_intrinsics(W, H)
    sensor = DepthSensor(K, W, H, noise=False)
    T = _down(1.3, tilt)
    depth, color = sensor.render(_plane(), T)
    # analytic depth: plane z_world = 0; a pixel ray d_cam = K^-1 [u v 1] (z = 1), world ray o + t R d_cam
    v, u = np.mgrid[0:H, 0:W]
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], -1)
    dz = d_cam @ T[2, :3]
    expected = -T[2, 3] / dz
    assert depth.dtype == np.float32 and depth.shape == (H, W) and color.shape == (H, W, 3)
    assert (depth > 0).all()
    assert np.abs(depth - expected).max() < 2e-6 * expected.max()


@pytest.mark.parametrize("z", [0.8, 1.6, 2.6])
def test_axial_noise_follows_the_nguyen_model(z):
    """Residuals on a plane tilted by 20 deg (so depths sweep the disparity steps) have the model's sigma."""
    K = kinect_v1_intrinsics(W * 2, H * 2)
    sensor = DepthSensor(K, W * 2, H * 2, noise=True, seed=1, missing_rate=0.0, edge_dropout=0.0, lateral_px=0.0)
    frame = sensor.render_frame(_plane(), _down(z, 20.0))
    valid = frame.depth > 0
    assert valid.mean() > 0.999
    truth = frame.true_depth[valid].astype(np.float64)
    err = frame.depth[valid].astype(np.float64) - truth
    sigma = np.sqrt(nguyen_axial_sigma(truth, np.deg2rad(20.0)) ** 2 + 0.001 ** 2 / 12)  # + mm quantisation
    r = err / sigma
    assert abs(r.std() - 1) < 0.05
    assert abs(r.mean()) < 0.05
    assert np.allclose(frame.depth[valid] * 1000, np.round(frame.depth[valid] * 1000), atol=1e-3)  # mm steps
    # disparity quantisation: far depths come in coarse steps (z^2 / (8 * 585 * 0.075))
    if z > 2:
        assert np.unique(frame.depth[valid]).size < 0.5 * np.unique(np.round(truth * 1000)).size
    assert nguyen_axial_sigma(2.6) > 4 * nguyen_axial_sigma(0.8)


def test_missing_pixels_range_limits_and_projector_shadow():
    K = kinect_v1_intrinsics(W, H)
    # random missing pixels at the requested rate on a plain plane
    s = DepthSensor(K, W, H, seed=2, missing_rate=0.05, edge_dropout=0.0)
    depth, _ = s.render(_plane(), _down(1.0))
    assert abs((depth == 0).mean() - 0.05) < 0.01
    # beyond max_range nothing is returned
    far = DepthSensor(K, W, H, max_range=1.0, noise=False).render(_plane(), _down(1.5))[0]
    assert (far == 0).all()
    # a box on the plane: the projector (at +x of the camera) cannot see the plane just left of the box
    box = o3d.geometry.TriangleMesh.create_box(0.2, 0.2, 0.3)
    box.translate((-0.1, -0.1, 0.0))
    scene = _plane() + box
    s = DepthSensor(K, W, H, seed=0, missing_rate=0.0, edge_dropout=0.0, lateral_px=0.0)
    depth, _ = s.render(scene, _down(1.2))
    truth = DepthSensor(K, W, H, noise=False).render(scene, _down(1.2))[0]
    top = np.abs(truth - 0.9) < 1e-3                       # the box top is 0.9 m away
    cols = np.flatnonzero(top.any(0))
    rows = np.flatnonzero(top.any(1))
    mid = slice(rows[0] + 3, rows[-1] - 3)
    left = depth[mid, cols[0] - 10:cols[0]]
    right = depth[mid, cols[-1] + 1:cols[-1] + 11]
    # shadow width = f * baseline * (1/z_top - 1/z_floor) pixels
    width = K[0, 0] * 0.075 * (1 / 0.9 - 1 / 1.2)
    assert abs((left == 0).sum(1).mean() - width) < 1.0
    assert (left[:, :4] > 0).all() and (right == 0).sum() == 0


def test_same_seed_same_frame_and_labels_match_objects():
    scene = make_tabletop_scene(1)
    K = kinect_v1_intrinsics(W, H)
    T = np.eye(4)
    T[:3, :3] = np.array([[-1, 0, 0], [0, 0.5, -np.sqrt(0.75)], [0, -np.sqrt(0.75), -0.5]]).T
    T[:3, 3] = (0.0, 0.75, 1.4)
    a = DepthSensor(K, W, H, seed=5).render_frame(scene, T, frame_seed=3)
    b = DepthSensor(K, W, H, seed=5).render_frame(scene, T, frame_seed=3)
    c = DepthSensor(K, W, H, seed=6).render_frame(scene, T, frame_seed=3)
    assert np.array_equal(a.depth, b.depth) and np.array_equal(a.color, b.color)
    assert not np.array_equal(a.depth, c.depth)
    assert np.array_equal(a.labels, c.labels) and np.array_equal(a.true_depth, c.true_depth)
    for o in scene.objects:
        mask = a.labels == scene.label_of(o.id)
        assert mask.sum() > 20, o.id
        mean = a.color[mask].mean(0) / 255
        # shading scales the albedo: the colour direction is the object's colour
        cos = mean @ np.asarray(o.colour) / np.linalg.norm(mean) / np.linalg.norm(o.colour)
        assert cos > 0.97, o.id


def test_bad_sensor_input_raises_config_error():
    K = kinect_v1_intrinsics(W, H)
    with pytest.raises(ConfigError, match="intrinsics"):
        DepthSensor(np.eye(2), W, H)
    with pytest.raises(ConfigError, match="range"):
        DepthSensor(K, W, H, min_range=2.0, max_range=1.0)
    bad = np.eye(4)
    bad[0, 0] = 2.0
    with pytest.raises(ConfigError, match="rotation"):
        DepthSensor(K, W, H).render(_plane(), bad)
    with pytest.raises(ConfigError, match="cannot render"):
        DepthSensor(K, W, H).render("scene.ply", np.eye(4))


def test_ideal_depth_is_the_noise_free_image_with_inf_where_nothing_is_hit():
    """The z-buffer image the evaluation compares with: the same rays as the sensor's noise-free render, no
    range limits, inf (not 0) where the ray hits nothing."""
    K = kinect_v1_intrinsics(W, H)
    scene = make_tabletop_scene(2, n_objects=3, floor=False)
    T = _down(2.0, 10.0)
    target = scene.raycasting_scene()
    z = ideal_depth(target.scene, K, W, H, T)
    exact = DepthSensor(K, W, H, noise=False, min_range=0.0, max_range=100.0).render(scene, T)[0]
    hit = np.isfinite(z)
    assert z.dtype == np.float32 and 0.2 < hit.mean() < 1.0  # no floor: rays beside the table hit nothing
    assert np.array_equal(z[hit], exact[hit]) and np.all(exact[~hit] == 0)


# ---- photometric effects (issue 12: auto-gain and colour-depth misregistration) -------------------------

def _tabletop_view():
    scene = make_tabletop_scene(seed=2)
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])
    T[:3, 3] = (0.0, 0.0, 1.6)
    return scene, T


def test_photometric_effects_are_off_by_default_and_leave_depth_alone():
    scene, T = _tabletop_view()
    K = kinect_v1_intrinsics(W, H)
    plain = DepthSensor(K, W, H, seed=5).render_frame(scene, T, frame_seed=3)
    same = DepthSensor(K, W, H, seed=5, gain_jitter=0.0, misregistration=(0, 0, 0)).render_frame(scene, T, frame_seed=3)
    assert np.array_equal(plain.color, same.color) and np.array_equal(plain.depth, same.depth)
    fx = DepthSensor(K, W, H, seed=5, gain_jitter=0.2, white_balance_jitter=0.05,
                     misregistration=(2, 1, 0.5)).render_frame(scene, T, frame_seed=3)
    assert np.array_equal(plain.depth, fx.depth) and np.array_equal(plain.labels, fx.labels)
    assert not np.array_equal(plain.color, fx.color)


def test_gain_scales_each_frame_by_one_factor_per_channel():
    scene, T = _tabletop_view()
    K = kinect_v1_intrinsics(W, H)
    ref = DepthSensor(K, W, H, noise=False).render(scene, T)[1].astype(float)
    sensor = DepthSensor(K, W, H, noise=False, gain_jitter=0.2, white_balance_jitter=0.05, seed=1)
    gains = []
    for _ in range(12):
        c = sensor.render(scene, T)[1].astype(float)
        ok = (ref > 40) & (ref < 150) & (c < 250)
        ratio = np.array([np.median(c[..., k][ok[..., k]] / ref[..., k][ok[..., k]]) for k in range(3)])
        spread = max(np.percentile(np.abs(c[..., k][ok[..., k]] - ratio[k] * ref[..., k][ok[..., k]]), 99)
                     for k in range(3))
        assert spread <= 1.5  # one gain per channel over the whole image (up to rounding)
        gains.append(ratio)
    log_g = np.log(np.array(gains))
    assert 0.1 < log_g.mean(axis=1).std() < 0.35  # frame to frame, about the 0.2 asked for
    assert np.abs(log_g - log_g.mean(axis=1, keepdims=True)).max() < 0.2  # white balance: small per channel


def test_misregistration_shifts_the_colour_image():
    scene, T = _tabletop_view()
    K = kinect_v1_intrinsics(W, H)
    ref = DepthSensor(K, W, H, noise=False).render_frame(scene, T)
    mis = DepthSensor(K, W, H, noise=False, misregistration=(2.0, -1.0, 0.0)).render_frame(scene, T)
    assert np.array_equal(ref.depth, mis.depth)
    # colour pixel (u, v) shows what the depth camera sees at (u + 2, v - 1)
    assert np.array_equal(mis.color[1:, :-2], ref.color[:-1, 2:])
    with pytest.raises(ConfigError):
        DepthSensor(K, W, H, misregistration=(1.0, np.nan, 0.0))


def test_misregistration_jitter_shifts_each_frame_by_its_own_whole_image_offset():
    """misregistration_jitter: the colour image of each frame is shifted by its own (du, dv) ~ N(0, sigma) per axis
    (unsynchronised streams of a moving camera), on top of the fixed misregistration; the same with a frame seed."""
    scene, T = _tabletop_view()
    K = kinect_v1_intrinsics(W, H)
    ref = DepthSensor(K, W, H, noise=False).render_frame(scene, T)
    sensor = DepthSensor(K, W, H, noise=False, misregistration=(1.0, 0.0, 0.0), misregistration_jitter=3.0, seed=4)
    shifts = []
    for k in range(8):
        f = sensor.render_frame(scene, T, frame_seed=k)
        assert np.array_equal(f.depth, ref.depth)
        assert np.array_equal(f.color, sensor.render_frame(scene, T, frame_seed=k).color)
        # the whole-pixel shift that best explains this frame's colour
        err = {(du, dv): np.mean(np.abs(np.roll(ref.color, (-dv, -du), axis=(0, 1))[8:-8, 8:-8].astype(int)
                                        - f.color[8:-8, 8:-8].astype(int)))
               for du in range(-8, 9) for dv in range(-8, 9)}
        shifts.append(min(err, key=err.get))
    du, dv = np.array(shifts, dtype=float).T
    assert len(set(shifts)) >= 4  # frames differ
    assert abs(du.mean() - 1.0) < 2.5 and np.abs(dv).mean() < 4.5  # about the fixed shift, a few px of jitter
    with pytest.raises(ConfigError):
        DepthSensor(K, W, H, misregistration_jitter=-1.0)
