"""Camera infos read the same way everywhere, and compared with a tolerance that means something.

Before: a rectified topic whose K is zero but whose P is valid was refused (K was checked before P was read);
nbv's intrinsics_from_recording read K for a rectified depth topic (fuse and export read P) and took the first
camera info topic with "depth" in its name, not the depth camera's; and `kinfu export` refused 1e-5 px of K jitter
(rtol 1e-9) with a message whose numbers were identical.
"""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.camera_info import image_camera, intrinsics_from_recording
from kinfu_cli.io.writers import RecordingWriter
from recordings import read_frames

S = 1_000_000_000
W, H = 20, 16
K = np.array([[30.0, 0, 9.5], [0, 30.0, 7.5], [0, 0, 1]])
P_RECT = np.array([[28.0, 0, 10.0, 0], [0, 28.0, 8.0, 0], [0, 0, 1, 0]])


def _info(w, topic, stamp, Kx=K, P=None):
    P = np.hstack([Kx, np.zeros((3, 1))]) if P is None else np.asarray(P, float)
    roi = w._type("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, width=0, height=0, do_rectify=False)
    msg = w._type("sensor_msgs/msg/CameraInfo")(
        header=w._header(topic, stamp, "cam"), height=H, width=W, distortion_model="plumb_bob", d=np.zeros(5),
        k=np.asarray(Kx, float).reshape(-1), r=np.eye(3).reshape(-1), p=P.reshape(-1), binning_x=0, binning_y=0,
        roi=roi)
    w._write(topic, "sensor_msgs/msg/CameraInfo", stamp, msg)


def _recording(path, depth_topic="/camera/depth/image_raw", info_topic="/camera/depth/camera_info", n=3,
               info=lambda i: {}, extra=None):
    with RecordingWriter(path) as w:
        for i in range(n):
            t = S + i * S // 10
            if extra:
                extra(w, i, t)
            _info(w, info_topic, t, **info(i))
            depth = (800 + 10 * i + np.arange(W * H).reshape(H, W)).astype(np.uint16)
            w.write_image(depth_topic, t, "cam", depth, "16UC1")
    return path


def _export(path, out):
    return CliRunner().invoke(cli, ["export", str(path), "-o", str(out), "-q", "--pose-source", "none"])


# ------------------------------------------------------------------------------------------- rectified, K zero
def test_a_rectified_topic_with_K_zero_and_a_valid_P_is_read_with_P(tmp_path):
    path = _recording(tmp_path / "rect_k0.mcap", depth_topic="/camera/depth/image_rect",
                      info=lambda i: {"Kx": np.zeros((3, 3)), "P": P_RECT})
    frames, stats = read_frames(path)
    assert len(frames) == 3  # before: RecordingError "CameraInfo K has no valid focal lengths"
    np.testing.assert_allclose(frames[0].K, P_RECT[:, :3])
    said = [n for n in stats.notes if "rectified" in n]
    assert len(said) == 1 and "K has no valid focal lengths" in said[0] and "fx=28" in said[0], stats.notes


def test_an_unrectified_topic_with_K_zero_is_still_refused():
    from types import SimpleNamespace

    import pytest

    from kinfu_cli.core.errors import RecordingError
    msg = SimpleNamespace(k=np.zeros(9), d=np.zeros(5), p=P_RECT.reshape(-1), width=W, height=H,
                          distortion_model="plumb_bob", binning_x=0, binning_y=0, roi=None)
    with pytest.raises(RecordingError, match="K has no valid focal lengths"):
        image_camera(msg, "rec: info", "/camera/depth/image_raw")
    assert image_camera(msg, "rec: info", "/camera/depth/image_rect").K[0, 0] == 28.0


# ------------------------------------------------------------------------------------------- nbv's intrinsics
def test_intrinsics_from_recording_reads_P_for_a_rectified_depth_topic(tmp_path):
    path = _recording(tmp_path / "rect.mcap", depth_topic="/camera/depth/image_rect",
                      info=lambda i: {"P": P_RECT})
    intr = intrinsics_from_recording(path)
    frames, _ = read_frames(path)
    assert intr["fx"] == 28.0 and intr["cx"] == 10.0  # before: K's 30 and 9.5
    assert intr["fx"] == frames[0].K[0, 0] and intr["cy"] == frames[0].K[1, 2]


def test_intrinsics_from_recording_takes_the_depth_cameras_info_topic(tmp_path):
    K_other = np.array([[50.0, 0, 9.5], [0, 50.0, 7.5], [0, 0, 1]])

    def extra(w, i, t):  # another camera info named "depth", logged before the depth camera's, with no images
        _info(w, "/a_depth_projector/camera_info", t, Kx=K_other)

    path = _recording(tmp_path / "two_infos.mcap", info_topic="/camera/depth/camera_info", extra=extra)
    intr = intrinsics_from_recording(path)
    frames, _ = read_frames(path)
    assert intr["fx"] == frames[0].K[0, 0] == 30.0


# ------------------------------------------------------------------------------------------- export: K jitter
def test_export_takes_negligible_K_jitter_as_one_camera(tmp_path):
    def jitter(i):
        Kj = K.copy()
        Kj[0, 0] += 1e-5 * i
        return {"Kx": Kj}

    res = _export(_recording(tmp_path / "jitter.mcap", info=jitter), tmp_path / "out")
    assert res.exit_code == 0, res.output  # before: rc 2 "changes ... fx=30 ... against ... fx=30"
    np.testing.assert_allclose(np.loadtxt(tmp_path / "out" / "camera-intrinsics.txt"), K)


def test_export_camera_change_message_shows_the_numbers_that_differ(tmp_path):
    def moved(i):
        Kj = K.copy()
        Kj[0, 0] += 0.002 * (i >= 1)
        return {"Kx": Kj}

    res = _export(_recording(tmp_path / "moved.mcap", info=moved), tmp_path / "out")
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinfu: error:"), res.output
    assert "fx=30.002" in lines[0] and "fx=30 " in lines[0] and "differs by up to 0.002 px" in lines[0]
