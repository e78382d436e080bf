"""The photometric term of projective ICP (fusion.photometric): it pins what depth alone cannot."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.camera import preset_intrinsics
from kinfu_cli.fusion.icp import data_pyramid, projective_icp
from kinfu_cli.fusion.photometric import PhotometricReference, intensity_pyramid
from kinfu_cli.fusion.tracking import FrameToModelTracker
from kinfu_cli.fusion.volume import TernaryVolume

W, H = 320, 240
WALL_Z = 1.2


def _texture(x, y):
    """Grey albedo of the wall at world (x, y): blotches a few centimetres across."""
    return 0.5 + 0.3 * np.sin(x * 40.0 + 2.0 * np.sin(y * 25.0)) * np.sin(y * 33.0 + 1.5 * np.sin(x * 21.0))


def _wall_frame(K, T_world_camera):
    """Depth and RGB of a textured fronto-parallel wall at z = WALL_Z (world) seen from T_world_camera (a pure
    translation in x, y)."""
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    z = WALL_Z - T_world_camera[2, 3]
    x = (u - K[0, 2]) / K[0, 0] * z + T_world_camera[0, 3]
    y = (v - K[1, 2]) / K[1, 1] * z + T_world_camera[1, 3]
    grey = np.clip(np.round(_texture(x, y) * 255), 0, 255).astype(np.uint8)
    return np.full((H, W), z, np.float32), np.repeat(grey[..., None], 3, axis=2)


def _model_maps(K, T_model):
    """The wall's vertex and normal maps (world) as the model ray cast from T_model shows them."""
    d, _ = _wall_frame(K, T_model)
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    verts = np.stack([(u - K[0, 2]) / K[0, 0] * d + T_model[0, 3], (v - K[1, 2]) / K[1, 1] * d + T_model[1, 3],
                      np.full_like(d, WALL_Z)], axis=-1).astype(np.float32)
    normals = np.zeros_like(verts)
    normals[..., 2] = -1.0
    return verts, normals


def test_texture_pins_a_slide_along_a_flat_wall():
    """The camera slid 12 mm / 7 mm along a flat wall since the reference frame: the point-to-plane error is the
    same at every slide, so ICP from the reference pose stays there; with the photometric term against the
    reference frame's intensities it finds the slide to a millimetre, and keeps the depth it had."""
    K = preset_intrinsics("kinect_v1", W, H)
    T_ref, T_now = np.eye(4), np.eye(4)
    T_now[:3, 3] = [0.012, -0.007, 0.0]
    d_ref, c_ref = _wall_frame(K, T_ref)
    d_now, c_now = _wall_frame(K, T_now)
    levels = data_pyramid(d_now, K, 3, 0.3, 4.0, bilateral=False)
    ref_levels = data_pyramid(d_ref, K, 3, 0.3, 4.0, bilateral=False)
    shapes = [lev.depth.shape for lev in levels]
    reference = PhotometricReference(intensity_pyramid(c_ref, None, shapes, gradients=True),
                                     [lev.depth for lev in ref_levels], T_ref)
    model_v, model_n = _model_maps(K, T_ref)
    kw = dict(iterations=(10, 10, 10), max_distance=(0.1, 0.1, 0.1), max_angle_deg=20.0)
    depth_only = projective_icp(levels, model_v, model_n, K, T_ref, T_ref, **kw)
    both = projective_icp(levels, model_v, model_n, K, T_ref, T_ref, **kw,
                          intensities=intensity_pyramid(c_now, None, shapes), reference=reference, photo_weight=0.03)
    slide = np.linalg.norm(T_now[:3, 3])
    assert np.linalg.norm(depth_only.T_world_camera[:3, 3] - T_now[:3, 3]) > 0.9 * slide
    assert np.linalg.norm(both.T_world_camera[:3, 3] - T_now[:3, 3]) < 0.001
    assert np.allclose(both.T_world_camera[:3, :3], np.eye(3), atol=2e-3)


def test_reference_needs_colour_in_the_depth_image_pixels():
    """keep_reference makes the fused frame the next one's reference only with colour in the depth image's
    pixels (its size, or that size resized: not another aspect ratio) and a photometric weight; the tracking then
    runs the term (its 'intensities' phase is timed)."""
    K = preset_intrinsics("kinect_v1", W, H)
    vol = TernaryVolume(size=(2.0, 2.0, 2.0), voxel_size=0.01, origin=(-1.0, -1.0, 0.0), min_depth=0.1, color=False)
    d, c = _wall_frame(K, np.eye(4))
    vol.integrate(d, K, np.eye(4))
    off = FrameToModelTracker(photo_weight=0.0)
    off.keep_reference(vol, d, K, np.eye(4), c)
    assert off._reference is None
    on = FrameToModelTracker(photo_weight=0.03)
    on.keep_reference(vol, d, K, np.eye(4), c[: H // 2])
    assert on._reference is None
    on.keep_reference(vol, d, K, np.eye(4), None)
    assert on._reference is None
    on.keep_reference(vol, d, K, np.eye(4), c)
    assert on._reference is not None
    on.track(vol, d, K, np.eye(4), color=c)
    assert on.timing.get("intensities", 0) > 0


@pytest.mark.parametrize("scale", [2.0, 0.5])
def test_colour_of_another_size_with_the_depth_aspect_ratio_is_resized(scale):
    """Colour at twice / half the depth's resolution in the depth camera's frame (a colour stream at 1280x960
    beside 640x480 depth, a decimated depth): fusion resizes it, and the colour term takes it too (it took none
    before); the slide along the textured wall is found as with colour at the depth's size."""
    import cv2

    K = preset_intrinsics("kinect_v1", W, H)
    vol = TernaryVolume(size=(2.0, 2.0, 2.0), voxel_size=0.01, origin=(-1.0, -1.0, 0.0), min_depth=0.1, color=False)
    T_now = np.eye(4)
    T_now[:3, 3] = [0.012, -0.007, 0.0]
    d_ref, c_ref = _wall_frame(K, np.eye(4))
    d_now, c_now = _wall_frame(K, T_now)
    size = (round(W * scale), round(H * scale))
    c_ref, c_now = cv2.resize(c_ref, size), cv2.resize(c_now, size)
    vol.integrate(d_ref, K, np.eye(4))
    tracker = FrameToModelTracker(photo_weight=0.03)
    tracker.keep_reference(vol, d_ref, K, np.eye(4), c_ref)
    assert tracker._reference is not None
    assert tracker.track(vol, d_now, K, np.eye(4), color=c_now).photometric  # (a flat wall: refused as degenerate)
    levels = data_pyramid(d_now, K, 3, 0.3, 4.0, bilateral=False)
    shapes = [lev.depth.shape for lev in levels]
    reference = PhotometricReference(intensity_pyramid(c_ref, None, shapes, gradients=True),
                                     [lev.depth for lev in data_pyramid(d_ref, K, 3, 0.3, 4.0, bilateral=False)],
                                     np.eye(4))
    model_v, model_n = _model_maps(K, np.eye(4))
    both = projective_icp(levels, model_v, model_n, K, np.eye(4), np.eye(4), iterations=(10, 10, 10),
                          max_distance=(0.1, 0.1, 0.1), max_angle_deg=20.0,
                          intensities=intensity_pyramid(c_now, None, shapes), reference=reference, photo_weight=0.03)
    assert np.linalg.norm(both.T_world_camera[:3, 3] - T_now[:3, 3]) < 0.002


def _walk(depths, colors, K, poses, photo_weight):
    """`kinfu fuse --pose icp` (its integrator, fusion.pipeline.track_frames) on 30 Hz frames of the synthetic room,
    the first fused at its true pose: (estimated poses, frames lost, frames re-localised)."""
    from kinfu_cli.fusion.pipeline import track_frames
    from kinfu_cli.io.frames import RGBDFrame

    vol = TernaryVolume(size=(6.0, 5.0, 3.0), voxel_size=6.0 / 512, origin=(-3.0, -2.5, -0.2), truncation=0.03,
                        color=False, min_depth=0.3, max_depth=4.0)
    frames = [RGBDFrame(i, round(i * 1e9 / 30), d, c, K, T) for i, (d, c, T) in enumerate(zip(depths, colors, poses))]
    r = track_frames(vol, frames, photometric_weight=photo_weight)
    return r.poses, len(r.lost), r.relocalised


@pytest.mark.parametrize("room", ["textured", "plain"])
def test_colour_holds_the_room_walk_where_depth_alone_slides(room):
    """200 frames of a hand-held walk through the synthetic room (Kinect noise, 320x240), panning to a wall and
    the floor: with the colour term the walk stays within a few centimetres, nothing lost, hardly a frame
    re-localised. Depth alone slides along the wall-floor line there (seed 1: 2.6-77 cm RMS over 10 runs while
    re-localisation varied from run to run; 15.0 cm, 12 frames lost, since it repeats to the bit; not asserted: a
    slide's size depends on the last digits of the arithmetic, which another platform's differ in). Papered
    walls (textured) or one colour per part (plain: only shading and the parts' edges); the plain room is the one
    that ran off (16 cm) when the term was left out of the coarsest pyramid level."""
    from kinfu_cli.fusion.tracking import ate_rmse
    from kinfu_cli.sim.paths import room_walk_poses
    from kinfu_cli.sim.room import make_room
    from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics, mesh_target

    w, h, seed = 320, 240, 1
    K = kinect_v1_intrinsics(w, h)
    scenario = make_room(seed=seed, width=w, height=h, frames=3)
    target = scenario.textured_target() if room == "textured" else mesh_target(scenario.mesh())
    sensor = DepthSensor(K, w, h, max_range=4.0, noise=True, seed=seed)
    poses = room_walk_poses(200, seed)
    frames = [sensor.render_frame(target, T, frame_seed=i) for i, T in enumerate(poses)]
    depths, colors = [f.depth for f in frames], [f.color for f in frames]
    est, lost, relocalised = _walk(depths, colors, K, poses, 0.03)
    ate = ate_rmse(est, poses)
    worst = max(np.linalg.norm(e[:3, 3] - T[:3, 3]) for e, T in zip(est, poses))
    print(f"{room} room walk seed {seed} 320x240 with colour: ATE {100 * ate:.2f} cm, max {100 * worst:.2f} cm, "
          f"{relocalised} re-localised")
    assert lost == 0 and ate < 0.035 and worst < 0.05 and relocalised <= 4
