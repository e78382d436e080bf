"""Recording contents a fuzz pass found handled badly: colour images of no pixels (a traceback), a rejected static
link at the TF root (fused in the wrong world frame with exit 0), and errors that named the wrong thing (the grid
size for depth that is all out of range or all invalid, the focal lengths for a NaN principal point, the grid for
focal lengths of no field of view)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from kinfu_cli.cli import cli
from kinfu_cli.core.camera import field_of_view_problem
from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.messages import camera_info_K
from kinfu_cli.io.undistort import check_distortion
from kinfu_cli.io.writers import RecordingWriter
from tests.conftest import one_line_error
from tests.recordings import H, K, T0, T_WRIST_CAM, W, S, T_base_wrist, depth_mm, read_frames

N = 8


def _tf_item(w, topic, stamp, parent, child, t, q):
    v = w._type("geometry_msgs/msg/Vector3")(x=float(t[0]), y=float(t[1]), z=float(t[2]))
    r = w._type("geometry_msgs/msg/Quaternion")(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))
    return w._type("geometry_msgs/msg/TransformStamped")(
        header=w._header(topic, stamp, parent), child_frame_id=child,
        transform=w._type("geometry_msgs/msg/Transform")(translation=v, rotation=r))


def _recording(path, *, colour_width=W, root_quaternion=(0.0, 0.0, 0.0, 1.0), depth=None):
    """The arm-camera recording of tests/recordings: world -> base_link (static, `root_quaternion`) -> wrist ->
    camera_optical, N depth frames (`depth(i)` as 32FC1 metres instead of depth_mm) with colour `colour_width`
    pixels wide (0: an empty image)."""
    with RecordingWriter(path) as w:
        q_cam = Rotation.from_matrix(T_WRIST_CAM[:3, :3]).as_quat()
        w._write("/tf_static", "tf2_msgs/msg/TFMessage", T0, w._type("tf2_msgs/msg/TFMessage")(transforms=[
            _tf_item(w, "/tf_static", T0, "world", "base_link", (0, 0, 0.7), root_quaternion),
            _tf_item(w, "/tf_static", T0, "wrist", "camera_optical", T_WRIST_CAM[:3, 3], q_cam)]))
        for k in range(40):
            stamp = T0 + k * S // 100
            w.write_tf(stamp, [("base_link", "wrist", T_base_wrist(k / 100))])
        for i in range(N):
            stamp = T0 + i * S // 30 + 20_000_000
            if depth is None:
                w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth_mm(i), "16UC1")
            else:
                w.write_image("/camera/depth/image_raw", stamp, "camera_optical", depth(i), "32FC1")
            w.write_camera_info("/camera/depth/camera_info", stamp, "camera_optical", K, W, H)
            msg = w._type("sensor_msgs/msg/Image")(
                header=w._header("/camera/color/image_raw", stamp, "camera_optical"), height=H if colour_width else 0,
                width=colour_width, encoding="rgb8", is_bigendian=0, step=3 * colour_width,
                data=np.full(H * colour_width * 3 if colour_width else 0, 90, np.uint8))
            w._write("/camera/color/image_raw", "sensor_msgs/msg/Image", stamp, msg)
    return path


def test_empty_colour_images_leave_their_frames_uncoloured_with_a_warning(tmp_path):
    # a colour image 0 pixels wide was taken for colour: fuse and export ended in an OpenCV traceback
    path = _recording(tmp_path / "empty_colour.mcap", colour_width=0)
    frames, stats = read_frames(path)
    assert len(frames) == N and all(f.color is None for f in frames)
    assert stats.color_empty == N and stats.without_color == N and stats.as_dict()["color_empty"] == N
    assert [w for w in stats.warnings("r") if "empty" in w] == [
        f"r: {N} colour images on /camera/color/image_raw paired with depth frames are empty (0 pixels wide or "
        f"high: a driver fault?); those frames carry no colour"]
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "out"), "--quiet", "--size", "1.5"])
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output and "colour images on /camera/color/image_raw" in res.output
    good = _recording(tmp_path / "colour.mcap")
    frames, stats = read_frames(good)
    assert all(f.color is not None and f.color.shape == (H, W, 3) for f in frames) and stats.color_empty == 0


@pytest.mark.parametrize("q", [(0.0, 0.0, 0.0, 0.0), (np.nan, 0.0, 0.0, 1.0)])
def test_a_rejected_static_link_at_the_root_is_an_error_not_another_world(tmp_path, q):
    # world -> base_link rejected (zero / NaN quaternion) left base_link as the root: fused there, 0.7 m off
    path = _recording(tmp_path / "root.mcap", root_quaternion=q)
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "out"), "--quiet"])
    one_line_error(res, "root.mcap", "stops at 'base_link'", "'world' -> 'base_link' were rejected",
                   "name the world frame to use 'base_link'")
    assert not (tmp_path / "out").exists()
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "base"), "--quiet", "--world-frame",
                                   "base_link", "--size", "1.5"])
    assert res.exit_code == 0, res.output
    # a hand frame whose every transform was rejected says so, not "not in the TF tree"
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "w"), "--quiet", "--world-frame", "world"])
    one_line_error(res, "world frame 'world' has no TF link", "'world' -> 'base_link' was rejected")


def test_all_invalid_depth_names_the_reason_with_the_automatic_grid(tmp_path):
    # with --size auto the reason was "no depth frames in the selection", which points at --start / --end
    path = _recording(tmp_path / "zero.mcap", depth=lambda i: np.zeros((H, W), np.float32))
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "out"), "--quiet"])
    one_line_error(res, "zero.mcap", "no usable depth frames (depth image has no valid pixel: 8)")


def test_depth_all_out_of_range_names_the_range_not_the_grid_size(tmp_path):
    # millimetres in a 32FC1 image: "--size: cannot size the grid ... (give the grid size)", which did not help
    path = _recording(tmp_path / "mm.mcap", depth=lambda i: depth_mm(i).astype(np.float32))
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "out"), "--quiet"])
    line = one_line_error(res, "mm.mcap", "lies in the depth range [0.3, 4] m", "millimetres stored as metres?")
    assert "--size" not in line
    path = _recording(tmp_path / "far.mcap", depth=lambda i: np.full((H, W), 9.0, np.float32))
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "out"), "--quiet"])
    line = one_line_error(res, "far.mcap", "readings from 9 to 9 m")
    assert "millimetres" not in line


def test_camera_info_names_the_entry_that_is_not_finite():
    k = [30.0, 0, float("nan"), 0, 30.0, 7.5, 0, 0, 1]
    with pytest.raises(RecordingError, match=r"/info: CameraInfo K has non-finite entries \(cx=nan\)"):
        camera_info_K(SimpleNamespace(k=k, width=W, height=H), "/info")
    with pytest.raises(RecordingError, match=r"no valid focal lengths \(fx=-30.0"):
        camera_info_K(SimpleNamespace(k=[-30.0] + k[1:2] + [9.5] + k[3:], width=W, height=H), "/info")


def test_a_field_of_view_of_no_width_is_refused_like_a_too_wide_one():
    huge = np.array([[1e9, 0, 9.5], [0, 1e9, 7.5], [0, 0, 1]])
    assert "under 0.5" in field_of_view_problem(huge, W, H)
    assert field_of_view_problem(K, W, H) is None  # 36 deg over the 20 px of the test camera
    assert field_of_view_problem(np.diag([600.0, 600.0, 1.0]), 20, 16) is None  # 1.9 deg: a tiny crop, kept


def test_equidistant_distortion_takes_four_coefficients_or_zeros_after_them():
    assert check_distortion("equidistant", [0.1, 0.01, 0, 0, 0], "/info")[1].tolist() == [0.1, 0.01, 0, 0]
    with pytest.raises(RecordingError, match=r"/info: equidistant distortion with 5 coefficients .*expected 4"):
        check_distortion("equidistant", [0.1, 0.01, 0, 0, 0.3], "/info")
