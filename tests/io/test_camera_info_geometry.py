"""CameraInfo geometry read as ROS's image_geometry PinholeCameraModel reads it (io.camera_info.image_camera):
roi and binning, P without distortion for a rectified topic, K of the pinhole form only; one K per exported folder;
a note when one of several depth topics is taken.

Before: an roi crop was taken for a resize (its intrinsics scaled by the size ratio, cx 6.9 cm off in the fuzz
data), binning was never read (binned images with distortion were refused without naming it), an image_rect topic
was undistorted a second time and read with K instead of P, a skewed K or one with K[2,2] = 2 was taken silently,
`kinfu export` wrote the first frame's K for frames of another K, and two depth topics gave no word of the choice.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.camera_info import image_camera, is_rectified_topic
from kinfu_cli.io.color_registration import colour_camera
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles
from kinfu_cli.io.writers import RecordingWriter
from recordings import read_frames

S = 1_000_000_000
W, H = 20, 16
K = np.array([[30.0, 0, 9.5], [0, 30.0, 7.5], [0, 0, 1]])
DEPTH, INFO = "/camera/depth/image_raw", "/camera/depth/camera_info"


def _depth(i: int) -> np.ndarray:
    return (800 + 10 * i + np.arange(W * H).reshape(H, W)).astype(np.uint16)


def _info(w, topic, stamp, Kx=K, size=(W, H), D=None, P=None, binning=(0, 0), roi=(0, 0, 0, 0), frame="cam"):
    """A CameraInfo with every field settable (RecordingWriter.write_camera_info has no roi, binning or P)."""
    P = np.hstack([Kx, np.zeros((3, 1))]) if P is None else np.asarray(P, float)
    roi_msg = w._type("sensor_msgs/msg/RegionOfInterest")(x_offset=roi[0], y_offset=roi[1], width=roi[2],
                                                          height=roi[3], do_rectify=False)
    msg = w._type("sensor_msgs/msg/CameraInfo")(
        header=w._header(topic, stamp, frame), height=size[1], width=size[0], distortion_model="plumb_bob",
        d=np.zeros(5) if D is None else np.asarray(D, float), k=np.asarray(Kx, float).reshape(-1),
        r=np.eye(3).reshape(-1), p=P.reshape(-1), binning_x=binning[0], binning_y=binning[1], roi=roi_msg)
    w._write(topic, "sensor_msgs/msg/CameraInfo", stamp, msg)


def _recording(path, n=3, crop=lambda d: d, depth_topic=DEPTH, info=lambda i: {}, extra=None):
    """n depth images (`crop` of the 20x16 ones) on depth_topic with a camera info each (`info(i)`: _info keywords)."""
    with RecordingWriter(path) as w:
        for i in range(n):
            t = S + i * S // 10
            _info(w, INFO, t, **info(i))
            w.write_image(depth_topic, t, "cam", np.ascontiguousarray(crop(_depth(i))), "16UC1")
            if extra:
                extra(w, i, t)
    return path


def _export(path, out, *args):
    return CliRunner().invoke(cli, ["export", str(path), "-o", str(out), "-q", "--pose-source", "none", *args])


def _msg(**kw):
    base = dict(k=K.reshape(-1), d=np.zeros(5), p=np.hstack([K, np.zeros((3, 1))]).reshape(-1), width=W, height=H,
                distortion_model="plumb_bob", binning_x=0, binning_y=0,
                roi=SimpleNamespace(x_offset=0, y_offset=0, width=0, height=0))
    return SimpleNamespace(**{**base, **kw})


# ------------------------------------------------------------------------------------------- roi and binning
def test_roi_moves_the_principal_point_and_binning_divides_the_intrinsics():
    roi = SimpleNamespace(x_offset=4, y_offset=3, width=10, height=8)
    cam = image_camera(_msg(roi=roi), "rec: info")
    assert (cam.width, cam.height) == (10, 8) and cam.reduction == "roi 10x8 at (4, 3) of 20x16"
    np.testing.assert_allclose(cam.K, [[30, 0, 5.5], [0, 30, 4.5], [0, 0, 1]])
    cam = image_camera(_msg(roi=roi, binning_x=2, binning_y=2), "rec: info")  # roi first, then binning
    assert (cam.width, cam.height) == (5, 4)
    np.testing.assert_allclose(cam.K, [[15, 0, 2.75], [0, 15, 2.25], [0, 0, 1]])


def test_an_roi_crop_is_read_with_its_offset_not_scaled_as_a_resize(tmp_path):
    path = _recording(tmp_path / "roi.mcap", crop=lambda d: d[3:11, 4:14], info=lambda i: {"roi": (4, 3, 10, 8)})
    frames, stats = read_frames(path)
    assert len(frames) == 3 and frames[0].depth.shape == (8, 10)
    np.testing.assert_allclose(frames[0].K, [[30, 0, 5.5], [0, 30, 4.5], [0, 0, 1]])  # before: fx 15, cx 4.5
    assert not [n for n in stats.notes if "scaled" in n], stats.notes


def test_binned_images_with_lens_distortion_are_read(tmp_path):
    path = _recording(tmp_path / "bin.mcap", crop=lambda d: d[::2, ::2],
                      info=lambda i: {"binning": (2, 2), "D": [0.05, 0, 0, 0, 0]})
    frames, stats = read_frames(path)  # before: "depth image ... is 10x8 but camera info ... says 20x16"
    assert len(frames) == 3
    np.testing.assert_allclose(frames[0].K, [[15, 0, 4.75], [0, 15, 3.75], [0, 0, 1]])


def test_images_that_do_not_fit_the_declared_binning_are_an_error_naming_it(tmp_path):
    path = _recording(tmp_path / "bin_full.mcap", info=lambda i: {"binning": (2, 2)})  # 20x16 images, binned info
    res = _export(path, tmp_path / "out")
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinfu: error:") and "binning 2x2 of 20x16" in lines[0]
    assert "is 20x16" in lines[0] and "Traceback" not in res.output


def test_a_colour_camera_publishing_an_roi_is_placed_with_its_offset(tmp_path):
    info = "/camera/color/camera_info"
    with RecordingWriter(tmp_path / "c.mcap") as w:
        _info(w, info, S, roi=(4, 3, 10, 8), frame="color")
    with open_recording(tmp_path / "c.mcap") as rec:
        lens, size = colour_camera(rec, info, image_topic="/camera/color/image_raw")
    assert size == (10, 8)  # before: (20, 16), the crop stretched over the whole colour camera
    np.testing.assert_allclose(lens.K, [[30, 0, 5.5], [0, 30, 4.5], [0, 0, 1]])


# ------------------------------------------------------------------------------------------- rectified topics
def test_rectified_topic_names():
    assert all(map(is_rectified_topic, ["/camera/depth/image_rect", "/camera/depth/image_rect_raw",
                                        "/kinect2/sd/image_depth_rect", "/camera/rgb/image_rect_color",
                                        "/camera/depth/image_rect_raw/compressedDepth"]))
    assert not any(map(is_rectified_topic, ["/camera/depth/image_raw", "/camera/direct/image", "/correct/depth",
                                            None]))


def test_an_image_rect_topic_is_read_with_P_and_not_undistorted_again(tmp_path):
    P = np.array([[28.0, 0, 10.0, 0], [0, 28.0, 8.0, 0], [0, 0, 1, 0]])
    path = _recording(tmp_path / "rect.mcap", depth_topic="/camera/depth/image_rect",
                      info=lambda i: {"D": [0.1, -0.2, 0, 0, 0.05], "P": P})
    frames, stats = read_frames(path)
    assert len(frames) == 3
    np.testing.assert_allclose(frames[0].K, P[:, :3])  # before: K
    np.testing.assert_array_equal(np.rint(frames[0].depth * 1000), _depth(0))  # before: remapped through D
    said = [n for n in stats.notes if "rectified" in n]
    assert len(said) == 1 and "/camera/depth/image_rect" in said[0] and "fx=28" in said[0], stats.notes


def test_a_rectified_topic_with_P_equal_to_K_and_no_distortion_says_nothing(tmp_path):
    path = _recording(tmp_path / "rect_plain.mcap", depth_topic="/camera/depth/image_rect_raw")
    frames, stats = read_frames(path)
    assert len(frames) == 3 and not stats.notes
    np.testing.assert_allclose(frames[0].K, K)


# ------------------------------------------------------------------------------------------- K of the wrong form
def _bad(K_bad):
    return lambda i: {"Kx": K_bad}


def test_a_K_not_of_the_pinhole_form_is_one_error_line(tmp_path):
    for name, change in (("skew", (0, 1, 3.0)), ("k22", (2, 2, 2.0)), ("k20", (2, 0, 0.001))):
        Kb = K.copy()
        Kb[change[0], change[1]] = change[2]
        path = _recording(tmp_path / f"{name}.mcap", info=_bad(Kb))
        res = _export(path, tmp_path / f"out_{name}")
        assert res.exit_code == 2, (name, res.output)
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("kinfu: error:"), (name, res.output)
        assert INFO in lines[0] and "not a pinhole camera matrix" in lines[0]
        assert f"K[{change[0]},{change[1]}]={change[2]:g}" in lines[0], lines[0]


def test_a_principal_point_off_the_image_is_a_warning(tmp_path):
    Kb = K.copy()
    Kb[0, 2] = 45.0  # on a 20 px wide image
    path = _recording(tmp_path / "cx.mcap", info=_bad(Kb))
    res = _export(path, tmp_path / "out")
    assert res.exit_code == 0, res.output
    said = [line for line in res.output.splitlines() if line.startswith("kinfu: warning:") and "principal" in line]
    assert len(said) == 1 and "cx=45" in said[0] and "outside its 20x16 image" in said[0], res.output


# ------------------------------------------------------------------------------------------- export: one K a folder
def test_export_refuses_frames_whose_camera_changes(tmp_path):
    K2 = K.copy()
    K2[0, 0] = K2[1, 1] = 35.0
    path = _recording(tmp_path / "change.mcap", n=4, info=lambda i: {"Kx": K if i < 2 else K2})
    res = _export(path, tmp_path / "out")
    assert res.exit_code == 2, res.output  # before: rc 0, camera-intrinsics.txt with fx 30 for all four
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "changes at depth frame 2" in lines[0] and "fx=35" in lines[0] and "fx=30" in lines[0]
    assert not (tmp_path / "out").exists()
    res = _export(path, tmp_path / "first", "--end", "0.15")  # the frames of one camera export as before
    assert res.exit_code == 0, res.output
    np.testing.assert_allclose(np.loadtxt(tmp_path / "first" / "camera-intrinsics.txt"), K)


# ------------------------------------------------------------------------------------------- two depth topics
def test_two_depth_topics_say_which_was_taken_and_how_to_choose(tmp_path):
    other = "/camera/aligned_depth_to_color/image_raw"

    def extra(w, i, t):
        w.write_image(other, t, "cam", _depth(i) + 80, "16UC1")

    path = _recording(tmp_path / "two.mcap", extra=extra)
    with open_recording(path) as rec:
        roles = detect_roles(rec)
        assert len(roles.notes) == 1 and "name the one to take as the depth topic" in roles.notes[0]
        assert "notes" not in roles.as_dict()
        assert detect_roles(rec, depth_topic=DEPTH).notes == []  # chosen: nothing to say
    res = _export(path, tmp_path / "out")
    assert res.exit_code == 0, res.output
    said = [line for line in res.output.splitlines() if line.startswith("kinfu: warning:") and "depth topics" in line]
    assert len(said) == 1 and other in said[0] and DEPTH in said[0] and "as the depth topic" in said[0], res.output
    doc = json.loads((tmp_path / "out" / "frames.json").read_text())
    assert any("2 depth topics" in w for w in doc["warnings"])
    res = CliRunner().invoke(cli, ["info", str(path)])
    assert res.exit_code == 0 and [line for line in res.output.splitlines()
                                   if "note:" in line and "2 depth topics" in line], res.output


def test_a_depth_topic_and_its_compressed_transport_are_one_stream(tmp_path):
    def extra(w, i, t):
        w.write_compressed_depth(f"{DEPTH}/compressedDepth", t, "cam", _depth(i))

    path = _recording(tmp_path / "transport.mcap", extra=extra)
    with open_recording(path) as rec:
        roles = detect_roles(rec)
    assert roles.depth_topic == DEPTH and roles.notes == []
