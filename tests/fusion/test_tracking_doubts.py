"""Tracked poses that look wrong although no frame was lost are reported (fusion/pipeline._tracking_doubts), and hint
mode's frames fused at their TF pose are told apart (_hint_falls_back, _fallback_warnings)."""

from __future__ import annotations

import numpy as np

from kinfu_cli.fusion.pipeline import (_fallback_warnings, _hint_falls_back, _narrow_frame_warnings, _pose_jump_warnings,
                                      _tracking_doubts, ate_vs_given)
from kinfu_cli.fusion.tracking import TrackResult


def track_log(dev_m: float, relocalised: int, n: int = 20) -> list[dict]:
    """n frames stepping 1 cm along x and 2 deg about z; the given poses `dev_m` away; the first `relocalised`
    found by re-localisation."""
    out = []
    for i in range(n):
        a = np.radians(2.0 * i)
        T = np.eye(4)
        T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        T[0, 3] = 0.01 * i
        out.append({"index": i, "lost": False, "relocalised": i < relocalised, "T_world_camera": T.tolist(),
                    "given_minus_tracked_m": dev_m})
    return out


def test_good_tracking_gives_no_warning():
    assert _tracking_doubts(track_log(0.007, 0)) == []
    assert _tracking_doubts(track_log(0.007, 4)) == []  # 20 % relocalised is tolerated
    assert _tracking_doubts([]) == []


def test_drift_from_the_given_poses_is_reported_with_the_motion_per_frame():
    w = _tracking_doubts(track_log(0.05, 0))
    assert len(w) == 1
    assert "5.0 cm RMS" in w[0] and "median 1.0 cm / 2.0 deg per frame" in w[0]


def test_frames_found_only_by_relocalisation_are_reported():
    log = track_log(0.0, 10)
    for t in log:
        del t["given_minus_tracked_m"]  # no given poses: the re-localisation share is the only evidence
    w = _tracking_doubts(log)
    assert len(w) == 1 and "10 of 20 tracked frames" in w[0] and "1.0 cm / 2.0 deg" in w[0]


def test_hint_mode_falls_back_to_the_tf_pose_unless_icp_found_it_wrong():
    T = np.eye(4)
    lost = TrackResult(T, 0.1, 0.01, True, "fitness 0.10 < 0.3")
    assert _hint_falls_back(lost)  # ICP could not refine: the TF pose is kept
    assert _hint_falls_back(TrackResult(T, 0.6, 0.01, False, relocalised=True))  # no better evidence than the TF
    assert not _hint_falls_back(TrackResult(T, 0.6, 0.01, False))  # refined by the first attempt
    far = TrackResult(T, 0.6, 0.01, True, "0.15 m / 2 deg from the TF pose", relocalised=True, tf_disagrees=True)
    assert not _hint_falls_back(far)  # a confident pose far from the TF: the TF is suspect, the frame is lost


def test_frames_fused_at_their_tf_pose_are_counted_apart_and_warned_about_past_max_lost():
    log = track_log(0.004, 0)
    for t in log[:5]:
        t.update(tf_fallback=True, given_minus_tracked_m=0.0, reason="fitness 0.02 < 0.3", check="fitness")
    log[5].update(tf_fallback=True, given_minus_tracked_m=0.0, reason="re-localised near the TF pose (not trusted)")
    assert ate_vs_given(log)["frames"] == 14  # the ICP-placed ones only
    w = _fallback_warnings(log, 0.10)
    assert len(w) == 1 and "only 14 of 20" in w[0] and "too little overlap: 5" in w[0]
    assert "only re-localisation found a pose: 1" in w[0]
    assert _fallback_warnings(log, 0.5) == [] and _fallback_warnings(track_log(0.0, 0), 0.0) == []


def test_a_run_tracked_only_because_tf_misses_the_camera_blames_the_missing_link_not_max_lost():
    """Pose mode chosen automatically: the recording has TF, but not to the depth frame, so ICP tracked; when too
    many frames are lost the error names that cause (the fix is naming the frames), not max_lost."""
    from types import SimpleNamespace

    import pytest

    from kinfu_cli.core.errors import RecordingError
    from kinfu_cli.fusion.pipeline import _tracking_verdict

    integrator = SimpleNamespace(lost=[1, 2], track_log=[{}] * 3, mode="icp", no_tf_link="")
    with pytest.raises(RecordingError) as plain:
        _tracking_verdict(integrator, 0.1, "rec.mcap")
    assert plain.value.parameter == "max_lost" and "give camera poses" in str(plain.value)
    why = "rec.mcap: the TF tree (10 frames) does not link camera frame cam to world: camera poses come from ICP"
    for bound in (None, 8):
        with pytest.raises(RecordingError) as err:
            _tracking_verdict(SimpleNamespace(**{**vars(integrator), "no_tf_link": why}), 0.1, "rec.mcap", bound)
        assert err.value.parameter is None
        assert "does not link camera frame cam to world" in str(err.value) and "give camera poses" not in str(err.value)


def test_a_camera_frame_that_is_the_world_frame_or_missing_is_said_plainly():
    """Depth images in the world frame were fused at the identity pose without a word; depth images without a
    frame_id were reported as 'camera frame ?'."""
    from types import SimpleNamespace

    from kinfu_cli.fusion.pipeline import _pose_plan
    from kinfu_cli.io.tf_buffer import TfBuffer

    tf = TfBuffer()
    tf.add("world", "base", 0, np.eye(4), static=True)
    rec = SimpleNamespace(path="rec.mcap")
    same = _pose_plan(rec, tf, SimpleNamespace(world_frame="world", camera_frame="world"), None, None)
    assert same.mode == "forced" and "fused at the identity pose" in same.warning
    missing = _pose_plan(rec, tf, SimpleNamespace(world_frame="world", camera_frame=None), None, None)
    assert missing.mode == "icp" and "the depth images carry no frame_id" in missing.warning
    fine = _pose_plan(rec, tf, SimpleNamespace(world_frame="world", camera_frame="base"), None, None)
    assert fine.warning == ""
    tracked = _pose_plan(rec, tf, SimpleNamespace(world_frame="world", camera_frame="world"), "icp", None)
    assert tracked.warning == ""  # ICP places the frames: not the identity


def test_many_frames_without_a_camera_pose_are_a_warning():
    """A camera whose TF chain broke for 12 of 30 frames was fused from the other 18, said only in report.json."""
    from kinfu_cli.fusion.pipeline import _pose_drop_warnings
    from kinfu_cli.io.frames import DROP_NO_POSE, FrameStats

    stats = FrameStats(depth_messages=30)
    stats.dropped[DROP_NO_POSE] = 2  # TF starting after the camera: usual
    assert _pose_drop_warnings(stats, "rec.mcap") == []
    stats.dropped[DROP_NO_POSE] = 12
    (warning,) = _pose_drop_warnings(stats, "rec.mcap")
    assert warning.startswith("rec.mcap: 12 of the 30 depth frames selected have no camera pose")
    assert "not fused" in warning
    # with --every 5 only 6 of the 30 were selected: 2 of them without a pose is a third, not 2 in 30
    every = FrameStats(depth_messages=30, skipped=24)
    every.dropped[DROP_NO_POSE] = 2
    (warning,) = _pose_drop_warnings(every, "rec.mcap")
    assert warning.startswith("rec.mcap: 2 of the 6 depth frames selected have no camera pose")


def test_icp_on_narrow_frames_is_said_to_be_doubtful():
    """6 identical 64x48 frames tracked with ICP drifted 46 cm with every check passed and no word: frames under
    MIN_TRACKING_WIDTH px are now warned about (given poses are not)."""
    from types import SimpleNamespace

    from kinfu_cli.fusion.tracking import MIN_TRACKING_WIDTH

    def run(width, tracked=True):
        return SimpleNamespace(tracker=object() if tracked else None, track_log=[{}] * 5,
                               intrinsics={"width": width, "height": width * 3 // 4})

    (w,) = _narrow_frame_warnings(run(64), "r.mcap")
    assert "ICP tracked 64x48 px depth frames, narrower than 160 px" in w and w.startswith("r.mcap: ")
    assert _narrow_frame_warnings(run(MIN_TRACKING_WIDTH), "r.mcap") == []
    assert _narrow_frame_warnings(run(64, tracked=False), "r.mcap") == []  # poses given, not tracked


def test_given_poses_that_jump_are_said():
    """A pose topic that put 3 of 12 frames 5 m away was fused silently with the default auto grid (it grew to 9.3 m
    to hold both copies of the scene): a given pose moving over 3 m/s between fused frames is now a warning."""
    from types import SimpleNamespace

    def run(xs, mode="topic", dt_s=0.2):
        poses = []
        for x in xs:
            T = np.eye(4)
            T[0, 3] = x
            poses.append(T)
        return SimpleNamespace(mode=mode, camera_poses=poses, camera_frames=list(range(len(xs))),
                               camera_stamps_ns=[int(i * dt_s * 1e9) for i in range(len(xs))])

    walk = [0.05 * i for i in range(12)]  # 0.25 m/s
    assert _pose_jump_warnings(run(walk), "r.bag") == []
    jumped = [x + (5.0 if 4 <= i <= 6 else 0.0) for i, x in enumerate(walk)]
    (w,) = _pose_jump_warnings(run(jumped), "r.bag")
    assert "jump at 2 fused frame(s) (4, 7; the largest 5.05 m in 0.200 s" in w and w.startswith("r.bag: ")
    assert _pose_jump_warnings(run(jumped, mode="icp"), "r.bag") == []  # tracking checks its own speed
