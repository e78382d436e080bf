"""`kinfu fuse --pose topic` end to end: a synthetic recording whose /camera/pose topic carries the true camera
poses (`kinfu synth --camera-pose-topic`), fused from TF and from the topic, a copy whose topic poses are shifted,
bad pose topics, and the pose-topic reader on real Odometry / PoseWithCovarianceStamped messages."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import TransformError
from kinfu_cli.core.grid import load_ternary
from kinfu_cli.io.frames import _PosePath, iter_frames
from kinfu_cli.io.messages import (camera_info_K, decode_depth, header_frame, header_stamp_ns,
                                   pose_message_to_matrix, transform_to_matrix)
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.tf_buffer import TfBuffer
from kinfu_cli.io.writers import RecordingWriter
from kinfu_cli.sim.scenario import load_ground_truth

POSE_TOPIC = "/camera/pose"
DEPTH_TOPIC = "/camera/depth/image_raw/compressedDepth"
CONTAINERS = ("recording.mcap", "recording.bag", "recording_ros2")
N_FRAMES = 6
FAST = ["--voxel-size", "0.02", "--size", "2.0", "--quiet"]
SHIFT_X = 0.1


def fuse(rec, out, *args):
    res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(out), *FAST, *args])
    assert res.exit_code == 0, res.output
    return load_ternary(out / "ternary.npz"), json.loads((out / "report.json").read_text())


@pytest.fixture(scope="module")
def posed(tmp_path_factory):
    """A small synthetic recording (all three containers) with the true camera poses on /camera/pose."""
    out = tmp_path_factory.mktemp("posed") / "rec"
    res = CliRunner().invoke(cli, ["synth", "-o", str(out), "--width", "64", "--height", "48", "--frames",
                                   str(N_FRAMES), "--seed", "3", "--camera-pose-topic", POSE_TOPIC, "--quiet"])
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def fused(posed, tmp_path_factory):
    """fused(container, mode) -> (TernaryGrid, report), each fused once per module."""
    cache = {}
    root = tmp_path_factory.mktemp("fused")

    def get(container: str, mode: str):
        if (container, mode) not in cache:
            args = ["--pose", "forced"] if mode == "forced" else ["--pose", "topic", "--pose-topic", POSE_TOPIC]
            cache[container, mode] = fuse(posed / container, root / f"{container}-{mode}", *args)
        return cache[container, mode]

    return get


def occupied_centroid(grid) -> np.ndarray:
    return grid.centers(np.argwhere(grid.labels == 1)).mean(axis=0)


@pytest.mark.parametrize("container", CONTAINERS)
def test_synth_pose_topic_is_the_tf_camera_pose_at_each_depth_stamp(posed, container):
    gt = load_ground_truth(posed)
    assert gt.info["topics"]["camera_pose"] == POSE_TOPIC
    with open_recording(posed / container) as rec:
        info = rec.topics[POSE_TOPIC]
        assert info.msgtypes == ["geometry_msgs/msg/PoseStamped"] and info.count == N_FRAMES
        tf = TfBuffer.from_recording(rec)
        msgs = [(header_stamp_ns(m), header_frame(m), pose_message_to_matrix(m, t))
                for _, t, _, m in rec.typed_messages([POSE_TOPIC])]
        depth_stamps = [f.stamp_ns for f in iter_frames(rec, pose_source="none")]
    assert [s for s, _, _ in msgs] == depth_stamps == gt.stamps_ns.tolist()
    camera = gt.info["camera"]["frame"]
    for (stamp, frame, T), T_true in zip(msgs, gt.poses):
        assert frame == "world"
        np.testing.assert_allclose(T, T_true, atol=1e-9)
        np.testing.assert_allclose(T, tf.lookup("world", camera, stamp), atol=1e-9)


@pytest.mark.parametrize("container", CONTAINERS)
def test_fuse_from_pose_topic_equals_fuse_from_tf(fused, container):
    g_tf, r_tf = fused(container, "forced")
    g_topic, r_topic = fused(container, "topic")
    assert g_topic.shape == g_tf.shape
    np.testing.assert_allclose(g_topic.origin, g_tf.origin, atol=1e-6)
    agree = float(np.mean(g_topic.labels == g_tf.labels))
    assert agree >= 0.999, agree
    assert r_topic["counts"]["occupied"] > 1000
    assert r_topic["pose_mode"] == "topic" and r_topic["pose_source"] == f"topic {POSE_TOPIC}"
    assert r_tf["pose_mode"] == "forced" and r_tf["pose_source"].startswith("tf world <- ")
    assert r_topic["frames"]["used"] == r_tf["frames"]["used"] == N_FRAMES
    assert r_topic["frames"]["dropped_total"] == 0 and r_topic["tracking"] is None


def copy_with_shifted_poses(src, dst, topic: str, dx: float, frame_from: int | None = None) -> None:
    """Copy the depth, camera info, TF and pose topics of `src` into `dst` (colour left out), moving every pose
    on `topic` by dx metres along world x. TF is copied unchanged. With frame_from = k, the poses on `topic`
    from its k-th message on claim frame_id "odom"."""
    n_pose = 0
    with open_recording(src) as rec, RecordingWriter(dst) as w:
        for name, msgtype, log_ns, msg in rec.typed_messages():
            kind = msgtype.split("/")[-1]
            if kind == "TFMessage":
                tfs = [(t.header.frame_id, t.child_frame_id, transform_to_matrix(t.transform)) for t in msg.transforms]
                w.write_tf(header_stamp_ns(msg.transforms[0]), tfs, static=name == "/tf_static")
                continue
            stamp, frame = header_stamp_ns(msg), header_frame(msg)
            if kind == "CameraInfo":
                K, width, height = camera_info_K(msg, name)
                w.write_camera_info(name, stamp, frame, K, width, height)
            elif name == DEPTH_TOPIC:
                mm = np.round(decode_depth(msg, name).astype(np.float64) * 1000.0).astype(np.uint16)
                w.write_compressed_depth(name, stamp, frame, mm)
            elif kind == "PoseStamped":
                T = pose_message_to_matrix(msg, msgtype)
                if name == topic:
                    T[0, 3] += dx
                    if frame_from is not None and n_pose >= frame_from:
                        frame = "odom"
                    n_pose += 1
                w.write_pose(name, stamp, frame, T)


def test_shifted_pose_topic_moves_the_fused_surface(posed, fused, tmp_path):
    """Topic poses 0.1 m off in x (TF left right): the surface fused from the topic moves by 0.1 m. One fixed grid
    of 1.5 cm voxels for both runs, so the moved surface is sampled on other voxel centres, not just relabelled."""
    shifted = tmp_path / "shifted.mcap"
    copy_with_shifted_poses(posed / "recording.mcap", shifted, POSE_TOPIC, SHIFT_X)
    _, report = fused("recording.mcap", "topic")
    grid = ["--voxel-size", "0.015", "--origin", ",".join(f"{v:.3f}" for v in report["grid"]["origin"])]
    topic = ["--pose", "topic", "--pose-topic", POSE_TOPIC]
    g_ref, _ = fuse(posed / "recording.mcap", tmp_path / "ref", *topic, *grid)
    g_shift, r_shift = fuse(shifted, tmp_path / "shift", *topic, *grid)
    assert r_shift["frames"]["used"] == N_FRAMES and r_shift["pose_source"] == f"topic {POSE_TOPIC}"
    shift = occupied_centroid(g_shift) - occupied_centroid(g_ref)
    assert abs(shift[0] - SHIFT_X) < 0.01, shift
    assert np.all(np.abs(shift[1:]) < 0.01), shift
    # the same surface, just moved (nothing clipped by the grid): occupied counts within 10 %
    n0, n1 = int((g_ref.labels == 1).sum()), int((g_shift.labels == 1).sum())
    assert abs(n1 - n0) < 0.1 * n0, (n0, n1)
    # TF in the copy is untouched: fusing the copy from TF gives back the unshifted surface
    g_tf, _ = fuse(shifted, tmp_path / "tf", "--pose", "forced", *grid)
    assert np.mean(g_tf.labels == g_ref.labels) >= 0.999


@pytest.mark.parametrize("topic, message", [
    ("/nope", "pose topic '/nope' not found"),
    (DEPTH_TOPIC, f"pose topic {DEPTH_TOPIC} carries sensor_msgs/msg/CompressedImage"),
    ("/camera/depth/camera_info", "pose topic /camera/depth/camera_info carries sensor_msgs/msg/CameraInfo"),
])
def test_bad_pose_topic_is_a_one_line_error(posed, tmp_path, topic, message):
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["fuse", str(posed / "recording.bag"), "-o", str(out), *FAST,
                                   "--pose", "topic", "--pose-topic", topic])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinfu: error:") and message in lines[0], res.output
    assert "Traceback" not in res.output
    assert not out.exists()


def test_pose_topic_option_is_required(posed, tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["fuse", str(posed / "recording.mcap"), "-o", str(out), *FAST, "--pose", "topic"])
    assert res.exit_code == 2 and "kinfu: error:" in res.output and "--pose-topic" in res.output
    assert not out.exists()


@pytest.mark.parametrize("topic, frame", [("/odom", "odom"), ("/amcl_pose", "map")])
def test_pose_topic_reader_on_real_odometry_and_amcl(shared_data, topic, frame):
    """The reader `kinfu fuse --pose topic` uses, on nav_msgs/Odometry and PoseWithCovarianceStamped of a real
    Nav2 recording: exact at message stamps, linear in translation halfway between, refuses far extrapolation."""
    path = shared_data("ros-recordings", "nav2_turtlebot.mcap")
    tol_ns = 50_000_000
    with open_recording(path) as rec:
        raw = [(header_stamp_ns(m), header_frame(m), pose_message_to_matrix(m, t))
               for _, t, _, m in rec.typed_messages([topic])]
        reader = _PosePath(rec, topic, tol_ns)
    assert len(raw) > 100 and reader.frame == frame and {f for _, f, _ in raw} == {frame}
    for i in (0, len(raw) // 3, len(raw) - 1):
        np.testing.assert_allclose(reader.pose(raw[i][0]), raw[i][2], atol=1e-9)
    (s0, _, T0), (s1, _, T1) = raw[len(raw) // 2], raw[len(raw) // 2 + 1]
    assert s1 > s0
    mid = reader.pose((s0 + s1) // 2)
    np.testing.assert_allclose(mid[:3, 3], (T0[:3, 3] + T1[:3, 3]) / 2, atol=1e-6)
    with pytest.raises(TransformError):
        reader.pose(raw[-1][0] + 10 * tol_ns)


@pytest.mark.parametrize("topic", ["camera/pose", "/hand/pose", "/tf"])
def test_synth_refuses_a_camera_pose_topic_it_cannot_write(tmp_path, topic):
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["synth", "-o", str(out), "--width", "64", "--height", "48", "--frames", "2",
                                   "--camera-pose-topic", topic, "--quiet"])
    assert res.exit_code == 2, res.output
    assert res.output.startswith("kinfu: error: --camera-pose-topic") and topic in res.output
    assert not out.exists()


def test_pose_topic_that_changes_frame_is_refused(posed, tmp_path):
    mixed = tmp_path / "mixed.mcap"
    copy_with_shifted_poses(posed / "recording.mcap", mixed, POSE_TOPIC, 0.0, frame_from=3)
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["fuse", str(mixed), "-o", str(out), "--pose", "topic", "--pose-topic", POSE_TOPIC,
                                   "--quiet"])
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinfu: error:") and POSE_TOPIC in lines[0]
    assert "'world'" in lines[0] and "'odom'" in lines[0] and not out.exists()


def test_a_pose_topic_given_means_pose_mode_topic_and_goes_with_no_other(posed, fused, tmp_path):
    # --pose-topic without --pose used to be ignored (TF poses, pose mode forced), with any other mode too
    rec = posed / "recording.mcap"
    grid, report = fuse(rec, tmp_path / "implied", "--pose-topic", POSE_TOPIC)
    assert report["pose_mode"] == "topic" and POSE_TOPIC in report["pose_source"]
    assert np.array_equal(grid.labels, fused("recording.mcap", "topic")[0].labels)
    for mode in ("forced", "icp"):
        res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(tmp_path / mode), *FAST, "--pose", mode,
                                       "--pose-topic", POSE_TOPIC])
        assert res.exit_code == 2 and res.output.startswith("kinfu: error: --pose-topic:"), res.output
        assert f"not {mode!r}" in res.output and not (tmp_path / mode).exists()
    res = CliRunner().invoke(cli, ["export", str(rec), "-o", str(tmp_path / "traj.tum"), "--trajectory", "tum",
                                   "--pose-source", "tf", "--pose-topic", POSE_TOPIC])
    assert res.exit_code == 2 and "--pose-topic" in res.output and "'tf'" in res.output
