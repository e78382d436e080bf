"""Frame-to-model ICP (pose modes icp / hint): synthetic sequence and real 7-Scenes frames."""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.camera import preset_intrinsics
from kinfu_cli.fusion.tracking import FrameToModelTracker, ate_rmse
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import box_scene
from kinfu_cli.sim.sensor import DepthSensor

W, H = 320, 240


def _track_sequence(frames, vol, tracker, first_T):
    est = [first_T]
    vol.integrate(frames[0][0], frames[0][2], first_T)
    results = []
    for d, K in ((f[0], f[2]) for f in frames[1:]):
        r = tracker.track(vol, d, K, est[-1])
        results.append(r)
        est.append(r.T_world_camera)
        vol.integrate(d, K, r.T_world_camera)
    return est, results


def test_icp_on_synthetic_sequence_within_2cm():
    rng = np.random.default_rng(1)
    K = preset_intrinsics("kinect_v1", W, H)
    sensor = DepthSensor(K, W, H, noise=False)
    poses = orbit_poses(16, radius=0.8, height=0.6, span_deg=60)
    scene = box_scene()
    frames = []
    for T in poses:  # exact depth + 2 mm Gaussian noise
        d = sensor.render(scene, T)[0]
        frames.append((np.where(d > 0, d + rng.normal(0, 0.002, d.shape).astype(np.float32), 0).astype(np.float32),
                       None, K, T))
    vol = TernaryVolume(size=(1.2, 1.2, 0.6), voxel_size=0.008, origin=(-0.6, -0.6, -0.1), min_depth=0.1,
                        color=False)
    est, results = _track_sequence(frames, vol, FrameToModelTracker(model_scale=0.5, voxel=0.01), poses[0])
    err = np.array([np.linalg.norm(e[:3, 3] - t[:3, 3]) for e, t in zip(est, poses)])
    assert err.mean() <= 0.02, err
    assert not any(r.lost for r in results)
    # no tracking (camera assumed still) would be far off
    assert ate_rmse([poses[0]] * len(poses), poses) > 5 * ate_rmse(est, poses)


def test_icp_on_7scenes_beats_no_tracking(shared_data):
    import cv2

    root = shared_data("rgbd-7scenes-redkitchen")
    K = np.loadtxt(root / "camera-intrinsics.txt")
    frames, truth = [], []
    for i in range(0, 60, 3):  # every 3rd frame: the same 2 s of motion, 20 frames to track
        raw = cv2.imread(str(root / f"frame-{i:06d}.depth.png"), cv2.IMREAD_UNCHANGED)
        d = np.where((raw > 0) & (raw < 65535), raw / 1000.0, 0).astype(np.float32)
        frames.append((d, None, K, None))
        truth.append(np.loadtxt(root / f"frame-{i:06d}.pose.txt"))
    from kinfu_cli.fusion.placement import default_origin

    origin = default_origin([(frames[0][0], K, truth[0])], 3.0)
    vol = TernaryVolume(size=3.0, resolution=200, origin=origin, truncation=0.04, color=False)
    est, results = _track_sequence(frames, vol, FrameToModelTracker(model_scale=0.25, voxel=0.02), truth[0])
    ate = ate_rmse(est, truth)
    ate_none = ate_rmse([truth[0]] * len(truth), truth)
    print(f"7-Scenes redkitchen 0-59 (every 3rd): ATE icp {ate * 100:.2f} cm, no tracking {ate_none * 100:.2f} cm")
    assert ate < 0.25 * ate_none
    assert ate < 0.03
    assert np.mean([r.fitness for r in results]) > 0.5


def test_lost_frame_keeps_initial_pose():
    """A depth image of something the model has never seen: tracking reports lost and keeps the hint."""
    K = preset_intrinsics("kinect_v1", W, H)
    T0 = orbit_poses(1, radius=0.8, height=0.6)[0]
    vol = TernaryVolume(size=(1.2, 1.2, 0.6), voxel_size=0.01, origin=(-0.6, -0.6, -0.1), min_depth=0.1, color=False)
    vol.integrate(DepthSensor(K, W, H, noise=False).render(box_scene(), T0)[0], K, T0)
    wall = np.full((H, W), 0.5, np.float32)  # a flat wall 0.5 m in front of the camera
    res = FrameToModelTracker().track(vol, wall, K, T0)
    assert res.lost and np.array_equal(res.T_world_camera, T0)


def test_icp_on_tabletop_box_with_line_artefacts(shared_data):
    """Real close-range frames whose depth lacks a row and a column every few pixels: with --fill-gaps'
    filter the model surface keeps its TSDF normals and ICP tracks every frame; as they come, too few model
    points have normals."""
    import cv2

    from kinfu_cli.fusion.filters import fill_gaps, range_filter

    root = shared_data("rgbd-tabletop-box")
    K = np.loadtxt(root / "intrinsics.K.txt")
    frames, truth = [], []
    for i in range(15, 55, 2):  # 20 frames, 1.3 s of hand-held motion
        raw = cv2.imread(str(root / f"frame-{i:06d}.depth.png"), cv2.IMREAD_UNCHANGED)
        d = range_filter(raw.astype(np.float32) / 1000.0, 0.1, 1.5)
        frames.append((fill_gaps(d, 2)[0], None, K, None))
        truth.append(np.loadtxt(root / f"frame-{i:06d}.pose.txt"))
    vol = TernaryVolume(size=(0.9, 0.7, 0.9), voxel_size=0.006, origin=(-0.45, -0.35, 0.1), truncation=0.02,
                        min_depth=0.1, max_depth=1.5, color=False)
    est, results = _track_sequence(frames, vol, FrameToModelTracker(), truth[0])
    ate = ate_rmse(est, truth)
    ate_none = ate_rmse([truth[0]] * len(truth), truth)
    print(f"tabletop-box 15-53 (every 2nd): ATE icp {ate * 100:.2f} cm, no tracking {ate_none * 100:.2f} cm")
    assert not any(r.lost for r in results)
    assert ate < 0.3 * ate_none
    assert ate < 0.02


def test_hint_mode_refuses_a_pose_far_from_the_tf_pose():
    """Hint mode: a TF pose 15 cm off, and the true pose as the second candidate (re-localisation finds it):
    TF and ICP disagree by more than a robot's TF errs, so the frame is lost, not fused at either pose. The
    same tracker without the hint flag accepts the pose it found."""
    from kinfu_cli.fusion.tracking import HINT_MAX_M

    K = preset_intrinsics("kinect_v1", W, H)
    poses = orbit_poses(3, radius=0.8, height=0.6, span_deg=10)
    sensor = DepthSensor(K, W, H, noise=False)
    vol = TernaryVolume(size=(1.2, 1.2, 0.6), voxel_size=0.008, origin=(-0.6, -0.6, -0.1), min_depth=0.1,
                        color=False)
    vol.integrate(sensor.render(box_scene(), poses[0])[0], K, poses[0])
    depth = sensor.render(box_scene(), poses[1])[0]
    tf = poses[1].copy()
    tf[:3, 3] += [0.15, 0.0, 0.0]
    free = FrameToModelTracker().track(vol, depth, K, [tf, poses[1]], T_ref=poses[0])
    assert not free.lost and np.linalg.norm(free.T_world_camera[:3, 3] - poses[1][:3, 3]) < 0.01
    hint = FrameToModelTracker(init_is_hint=True).track(vol, depth, K, [tf, poses[1]], T_ref=poses[0])
    assert hint.lost and "from the TF pose" in hint.reason and HINT_MAX_M < 0.15
