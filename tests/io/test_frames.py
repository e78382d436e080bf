"""Frame assembly and role detection on small recordings written by RecordingWriter (all three containers)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinfu_cli.core.errors import ConfigError, RecordingError, TransformError
from kinfu_cli.io.frames import DROP_NO_POSE, FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles

from recordings import (K, S, T0, T_WORLD_BASE, T_WRIST_CAM, H, W, T_base_wrist, color, depth_mm,  # noqa: F401
                        expected_pose, make_recording)


@pytest.mark.parametrize("name", ["r.mcap", "r.bag", "r_ros2"])
def test_frames_pair_depth_colour_intrinsics_and_pose(tmp_path, name):
    path = make_recording(tmp_path / name)
    with open_recording(path) as rec:
        roles = detect_roles(rec)
        assert roles.depth_topic == "/camera/depth/image_raw"
        assert roles.color_topic == "/camera/color/image_raw"
        assert roles.info_topic == "/camera/depth/camera_info"
        assert roles.camera_frame == "camera_optical" and roles.world_frame == "world"
        stats = FrameStats()
        frames = list(iter_frames(rec, roles, stats=stats))
    assert [f.index for f in frames] == list(range(12))
    assert stats.used == 12 and stats.dropped_total == 0 and stats.without_color == 0
    for i, f in enumerate(frames):
        assert f.depth.dtype == np.float32 and f.depth.shape == (H, W)
        np.testing.assert_array_equal(f.depth, depth_mm(i).astype(np.float32) * np.float32(0.001))
        np.testing.assert_array_equal(f.color, color(i))  # the colour of the same instant, not a neighbour
        np.testing.assert_array_equal(f.K, K)
        np.testing.assert_allclose(f.T_world_camera, expected_pose(f.stamp_ns), atol=1e-9)


def test_tolerance_drops_and_window(tmp_path):
    # colour 8 ms after depth, every other frame only; TF starts 0.2 s late
    path = make_recording(tmp_path / "r.mcap", n=15, color_offset_ns=8_000_000, color_every=2, tf_from=0.2)
    with open_recording(path) as rec:
        roles = detect_roles(rec)
        stats = FrameStats()
        frames = list(iter_frames(rec, roles, tolerance_s=0.005, stats=stats))
        # depth at 0.05 + i/30 s; TF from 0.2 s (5 ms tolerance): frames 0..4 have no pose
        assert stats.dropped == {DROP_NO_POSE: 5}
        assert [f.index for f in frames] == list(range(5, 15))
        assert all(f.color is None for f in frames)  # 8 ms > 5 ms tolerance
        stats = FrameStats()
        frames = list(iter_frames(rec, roles, tolerance_s=0.02, stats=stats))
        # frame 4 (0.183 s) is now within the tolerance of the first TF sample (0.2 s)
        assert [f.index for f in frames] == list(range(4, 15)) and stats.dropped == {DROP_NO_POSE: 4}
        assert [f.color is not None for f in frames] == [i % 2 == 0 for i in range(4, 15)]
        assert stats.without_color == 5  # odd frames: nearest colour is 25 ms away
        for f in frames:
            if f.color is not None:
                np.testing.assert_array_equal(f.color, color(f.index))
        # every other frame of a window; no pose needed
        stats = FrameStats()
        frames = list(iter_frames(rec, roles, pose_source="none", every=2, start_s=0.1, end_s=0.35,
                                  stats=stats))
        assert [f.T_world_camera for f in frames] == [None] * len(frames)
        stamps = np.array([(f.stamp_ns - rec.start_ns) / S for f in frames])
        assert np.all((stamps >= 0.1) & (stamps <= 0.35))
        assert len(frames) == 4 and stats.depth_messages == 8 and stats.skipped == 4


def test_pose_topic_source_and_compressed_depth(tmp_path):
    path = make_recording(tmp_path / "r.bag", n=6, compressed=True, hand=True)
    with open_recording(path) as rec:
        roles = detect_roles(rec)
        assert roles.depth_topic == "/camera/depth/image_raw/compressedDepth"
        assert roles.hand_topic == "/hand/pose"
        frames = list(iter_frames(rec, roles))
        assert len(frames) == 6
        np.testing.assert_array_equal(frames[3].depth, depth_mm(3).astype(np.float32) * np.float32(0.001))
        # the hand topic as a "camera pose" topic: poses interpolate between its messages
        frames = list(iter_frames(rec, roles, pose_source="topic", pose_topic="/hand/pose"))
        for f in frames:
            x = 0.1 * ((f.stamp_ns - T0) / S * 100) / 100
            np.testing.assert_allclose(f.T_world_camera[:3, 3], [x, 0.2, 0.3], atol=1e-9)


def test_32fc1_depth(tmp_path):
    path = make_recording(tmp_path / "r_ros2", n=3, depth_encoding="32FC1")
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, pose_source="none"))
    np.testing.assert_allclose(frames[2].depth, depth_mm(2) / 1000.0, rtol=1e-7)


def test_bad_recordings_raise_clear_errors(tmp_path):
    with open_recording(make_recording(tmp_path / "noinfo.mcap", n=2, info=False)) as rec:
        with pytest.raises(RecordingError, match="no sensor_msgs/CameraInfo topic for depth topic /camera/depth"):
            list(iter_frames(rec))
    with open_recording(make_recording(tmp_path / "size.mcap", n=2, info_size=(640, 480))) as rec:
        with pytest.raises(RecordingError, match="20x16 but camera info /camera/depth/camera_info says 640x480"):
            list(iter_frames(rec))
    with open_recording(make_recording(tmp_path / "enc.mcap", n=2, depth_encoding="mono8")) as rec:
        roles = detect_roles(rec, depth_topic="/camera/depth/image_raw")
        with pytest.raises(RecordingError, match="/camera/depth/image_raw: depth encoding 'mono8' is not supported"):
            list(iter_frames(rec, roles))
    with open_recording(make_recording(tmp_path / "ok.mcap", n=2)) as rec:
        with pytest.raises(RecordingError, match=r"depth topic '/nope' not found \(available topics: .*/tf"):
            detect_roles(rec, depth_topic="/nope")
        with pytest.raises(TransformError, match="'camera_ir' is not in the TF tree") as exc:
            detect_roles(rec, camera_frame="camera_ir")  # a named frame must exist: no silent fallback
        assert exc.value.parameter == "camera_frame"
        with pytest.raises(ConfigError, match="every"):
            list(iter_frames(rec, every=0))


def test_colour_that_never_pairs_with_the_depth_frames_is_warned_about(tmp_path):
    # colour stamped 100 ms after each depth image, over the 50 ms tolerance: every surface stayed black, silently
    late = make_recording(tmp_path / "late.mcap", n=6, fps=2.0, color_offset_ns=100_000_000)
    with open_recording(late) as rec:
        stats = FrameStats()
        frames = list(iter_frames(rec, detect_roles(rec), stats=stats))
    assert len(frames) == 6 and all(f.color is None for f in frames) and stats.color_unpaired == 6
    w = [x for x in stats.warnings("late.mcap") if "have no colour" in x]
    assert len(w) == 1 and "6 of 6 frames" in w[0] and "100 ms from a depth frame" in w[0] and "50 ms" in w[0]
    with open_recording(late) as rec:  # a tolerance that reaches them pairs them
        stats = FrameStats()
        assert all(f.color is not None for f in iter_frames(rec, detect_roles(rec), stats=stats, tolerance_s=0.12))
    assert stats.color_unpaired == 0 and not [x for x in stats.warnings("late.mcap") if "have no colour" in x]


def _infos_recording(path, infos):
    """Depth images in camera_optical (no TF) and the camera infos `infos`: (topic, frame, K)."""
    from kinfu_cli.io.writers import RecordingWriter

    with RecordingWriter(path) as w:
        for i in range(3):
            stamp = T0 + i * S // 10
            w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i), "16UC1")
            for topic, frame, k in infos:
                w.write_camera_info(topic, stamp, frame, k, W, H)
    return path


def test_a_camera_info_in_the_depth_frame_wins_and_one_in_another_frame_is_warned_about(tmp_path):
    # the colour camera's info (another lens) was taken as the depth intrinsics without a word
    colour_K = K.copy()
    colour_K[0, 0] = colour_K[1, 1] = 45.0
    only_colour = _infos_recording(tmp_path / "c.mcap", [("/camera/color/camera_info", "camera_color", colour_K)])
    with open_recording(only_colour) as rec:
        stats = FrameStats()
        frames = list(iter_frames(rec, detect_roles(rec), stats=stats, pose_source="none"))
    assert len(frames) == 3 and frames[0].K[0, 0] == 45.0
    w = [x for x in stats.warnings("c.mcap") if "may be another camera's" in x]
    assert len(w) == 1 and "'camera_color'" in w[0] and "'camera_optical'" in w[0]
    both = _infos_recording(tmp_path / "b.mcap", [("/camera/color/camera_info", "camera_color", colour_K),
                                                   ("/ir/info", "camera_optical", K)])
    with open_recording(both) as rec:  # the namespace prefers the colour one; the frame decides
        roles = detect_roles(rec)
        stats = FrameStats()
        frames = list(iter_frames(rec, roles, stats=stats, pose_source="none"))
    assert roles.info_topic == "/ir/info" and frames[0].K[0, 0] == 30.0
    assert not [x for x in stats.warnings("b.mcap") if "another camera's" in x]
