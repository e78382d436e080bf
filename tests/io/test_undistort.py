"""Depth from a camera with lens distortion (CameraInfo D) is remapped to the pinhole K before it is used: a tilted
plane seen through a plumb_bob lens stays flat."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.undistort import Undistorter, check_distortion
from kinfu_cli.io.writers import RecordingWriter

W, H = 160, 120
K = np.array([[110.0, 0, 79.5], [0, 110.0, 59.5], [0, 0, 1]])
D = np.array([-0.28, 0.09, 0.001, -0.0005, -0.01])  # a wide lens' barrel distortion
PLANE_N = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])  # n . X = PLANE_D, tilted to the camera
PLANE_D = -1.2


def _distorted_depth() -> np.ndarray:
    """z-depth of the plane at each pixel of the distorted image: the pixel's ray is its undistorted direction."""
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    xy = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2), K, D).reshape(-1, 2)
    rays = np.c_[xy, np.ones(len(xy))]
    z = PLANE_D / (rays @ PLANE_N)
    return z.reshape(H, W).astype(np.float32)


def _plane_rms(depth: np.ndarray) -> float:
    v, u = np.nonzero(depth > 0)
    z = depth[v, u].astype(np.float64)
    pts = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], 1)
    return float(np.sqrt(np.mean((pts @ PLANE_N - PLANE_D) ** 2)))


def test_depth_through_a_lens_is_remapped_to_the_pinhole_camera(tmp_path):
    depth = _distorted_depth()
    assert _plane_rms(depth) > 0.01  # read as pinhole, the plane bends by centimetres
    path = tmp_path / "lens.mcap"
    with RecordingWriter(path) as w:
        for i in range(2):
            t = 10**9 + i * 10**8
            w.write_image("/camera/depth/image_raw", t, "camera_optical", np.round(depth * 1000).astype(np.uint16),
                          "16UC1")
            w.write_camera_info("/camera/depth/camera_info", t, "camera_optical", K, W, H, D)
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, pose_source="none"))
    assert len(frames) == 2
    got = frames[0].depth
    assert np.mean(got > 0) > 0.9  # the corners the lens does not reach stay empty
    assert _plane_rms(got) < 0.002


def test_distortion_models():
    assert check_distortion("plumb_bob", [0, 0, 0, 0, 0], "/info")[1].size == 0
    assert check_distortion("", None, "/info")[1].size == 0
    model, d = check_distortion("rational_polynomial", np.arange(1, 9) * 0.01, "/info")
    assert model == "rational_polynomial" and d.size == 8
    assert check_distortion("equidistant", [0.1, 0.01, 0, 0], "/info")[0] == "equidistant"
    with pytest.raises(RecordingError, match="/info: distortion model 'division'"):
        check_distortion("division", [0.1], "/info")
    with pytest.raises(RecordingError, match="/info: plumb_bob distortion with 3 coefficients"):
        check_distortion("plumb_bob", [0.1, 0.0, 0.0], "/info")


def test_projection_through_the_lens_inverts_the_remap():
    lens = Undistorter(K, "plumb_bob", D)
    pts = np.array([[0.1, -0.05, 1.0], [-0.3, 0.2, 1.5]])
    uv = lens.project(pts)
    back = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, D).reshape(-1, 2)
    np.testing.assert_allclose(back, pts[:, :2] / pts[:, 2:], atol=1e-6)
