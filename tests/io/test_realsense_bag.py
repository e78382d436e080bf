"""A RealSense SDK recording (RealSense Viewer / librealsense .bag): topics under /device_0/, depth in the
sensor's Depth Units, colour from the colour camera beside the depth camera, placed through the streams' own
extrinsics (/device_0/sensor_<i>/<Stream>_<n>/tf/<reference>), not through /tf.

The bags are written here in the layout librealsense's "Realsense Record and Playback" document gives (no real
SDK bag was available): header frame_ids empty, static information (camera infos, options, extrinsics) at time
0, each stream's extrinsics mapping the reference stream's points into that stream's frame."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

from kinfu_cli.cli import cli
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import primitive_tabletop_scene
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

S = 1_000_000_000
WD, HD = 160, 120  # depth camera
WC, HC = 200, 150  # colour camera: its own size and focal length
K_COLOR = np.array([[185.0, 0, 99.0], [0, 185.0, 76.0], [0, 0, 1]])
T_DEPTH_COLOR = np.eye(4)  # the colour optical frame in the depth optical frame: 15 mm to the side, turned 1 deg
T_DEPTH_COLOR[:3, :3] = Rotation.from_euler("y", 1.0, degrees=True).as_matrix()
T_DEPTH_COLOR[:3, 3] = [0.015, 0.0, 0.0]
T_DEPTH_REF = np.eye(4)  # the reference stream (extrinsics group 0) is not the depth stream here: 5 mm beside it
T_DEPTH_REF[:3, 3] = [-0.005, 0.001, 0.0]
DEPTH = "/device_0/sensor_0/Depth_0"
COLOR = "/device_0/sensor_1/Color_0"


def _through_lens(render, D):
    """render(K, w, h) -> pinhole RGB; the colour camera's (K_COLOR, WC x HC) image through the lens D (plumb_bob
    form): each pixel takes the pinhole colour where its undistorted ray meets a wider pinhole image."""
    if D is None:
        return render(K_COLOR, WC, HC)
    pad = 40
    K_wide = K_COLOR.copy()
    K_wide[:2, 2] += pad
    wide = render(K_wide, WC + 2 * pad, HC + 2 * pad)
    u, v = np.meshgrid(np.arange(WC, dtype=np.float64), np.arange(HC, dtype=np.float64))
    uv = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2), K_COLOR, D, P=K_wide)
    maps = uv.reshape(HC, WC, 2).astype(np.float32)
    return cv2.remap(wide, maps[..., 0], maps[..., 1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)


def write_sdk_bag(path, units: float | None = 0.001, color_tf: bool = True, frames: int = 3,
                  span_deg: float = 60.0, color_D=None, color_model: str = "Inverse Brown Conrady",
                  image_units: float | None = None):
    """A RealSense SDK-layout bag of the tabletop scene; returns [(rendered depth m, colour the depth camera
    sees)] per frame. units: the Depth Units option (None: not recorded); color_D: the colour lens' distortion,
    recorded as `color_model` (the SDK's name); image_units: append a float32 depth_units to every image (depth:
    this value, colour: 0), as recent librealsense versions do (and units then default to it)."""
    scene = primitive_tabletop_scene(seed=4)
    K_depth = kinect_v1_intrinsics(WD, HD)
    depth_cam = DepthSensor(K_depth, WD, HD, noise=False)
    poses = orbit_poses(frames, radius=0.85, height=1.3, target=(0.0, 0.0, 0.75), start_deg=30.0,
                        span_deg=span_deg)
    scale = units or image_units or 0.001
    trailer = {} if image_units is None else {"depth": np.float32(image_units).tobytes(),
                                              "color": np.float32(0).tobytes()}
    truth = []
    with RecordingWriter(path) as w:
        w.write_camera_info(f"{DEPTH}/info/camera_info", 0, "", K_depth, WD, HD)
        w.write_camera_info(f"{COLOR}/info/camera_info", 0, "", K_COLOR, WC, HC, color_D, color_model)
        if units is not None:
            w.write_float32("/device_0/sensor_0/option/Depth Units/value", 0, units)
        w.write_float32("/device_0/sensor_1/option/Exposure/value", 0, 156.0)
        w.write_transform(f"{DEPTH}/tf/0", 0, np.linalg.inv(T_DEPTH_REF))  # reference -> depth
        if color_tf:  # reference -> colour
            w.write_transform(f"{COLOR}/tf/0", 0, np.linalg.inv(T_DEPTH_COLOR) @ np.linalg.inv(T_DEPTH_REF))
        for i, T in enumerate(poses):
            t = S + i * S // 30
            depth, own = depth_cam.render(scene, T)
            rgb = _through_lens(lambda K, w, h: DepthSensor(K, w, h, noise=False).render(scene, T @ T_DEPTH_COLOR)[1],
                                color_D)
            raw = np.round(depth / scale)
            raw[raw > 65534] = 0
            truth.append((np.where(raw > 0, depth, 0.0), own))
            w.write_image(f"{DEPTH}/image/data", t, "", raw.astype(np.uint16), "mono16", trailer.get("depth", b""))
            w.write_image(f"{COLOR}/image/data", t + 2_000_000, "", rgb, "rgb8", trailer.get("color", b""))
    return truth


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """{units: (bag path, truth)} for 1 mm and 0.1 mm depth units."""
    root = tmp_path_factory.mktemp("sdk_bags")
    return {u: (root / f"u{u}.bag", write_sdk_bag(root / f"u{u}.bag", u)) for u in (0.001, 0.0001)}


def _frames(path, **kwargs):
    stats = FrameStats()
    with open_recording(path) as rec:
        frames = list(iter_frames(rec, pose_source="none", stats=stats, **kwargs))
    return frames, stats


@pytest.mark.parametrize("units", [0.001, 0.0001])
def test_depth_is_read_in_the_recorded_depth_units(bags, units):
    path, truth = bags[units]
    frames, stats = _frames(path)
    assert len(frames) == len(truth)
    for f, (depth, _) in zip(frames, truth):
        valid = depth > 0
        assert valid.mean() > 0.5 and np.array_equal(f.depth > 0, valid)
        # the rendered depth, but for the rounding to one depth unit
        assert np.abs(f.depth[valid] - depth[valid]).max() <= units / 2 + 1e-6
    assert stats.as_dict()["depth_units_m"] == pytest.approx(units)  # (report.json's frames say the scale used)


def test_colour_is_placed_through_the_streams_extrinsics(bags):
    path, truth = bags[0.001]
    frames, stats = _frames(path)
    reg = stats.color_registration
    assert reg["mode"] == "project" and reg["color_info_topic"] == f"{COLOR}/info/camera_info"
    # reference -> stream extrinsics composed: the colour camera's pose in the depth camera's frame, inverted
    np.testing.assert_allclose(reg["T_color_depth"], np.linalg.inv(T_DEPTH_COLOR), atol=1e-5)
    for f, (depth, own) in zip(frames, truth):
        seen = f.color_mask
        valid = depth > 0
        assert seen[valid].mean() > 0.9 and not seen[~valid].any()
        err = np.abs(f.color.astype(int) - own.astype(int)).max(axis=2)[seen]
        assert np.mean(err > 30) < 0.05, np.mean(err > 30)


def test_kinfu_info_names_the_layout_the_depth_units_and_the_colour_placement(bags):
    path, _ = bags[0.0001]
    res = CliRunner().invoke(cli, ["info", str(path)])
    assert res.exit_code == 0, res.output
    assert "RealSense SDK recording" in res.output
    assert "0.1 mm per unit (from /device_0/sensor_0/option/Depth Units/value)" in res.output
    assert "through the recorded stream extrinsics (15.0 mm apart)" in res.output
    res = CliRunner().invoke(cli, ["info", str(path), "--json"])
    summary = json.loads(res.output)
    assert summary["realsense"]["depth_units_m"] == pytest.approx(0.0001)
    assert summary["roles"]["depth_topic"] == f"{DEPTH}/image/data"
    assert summary["roles"]["color_topic"] == f"{COLOR}/image/data"
    res = CliRunner().invoke(cli, ["info", str(path), "--frames"])  # TF poses by default: there are none
    assert res.exit_code == 2 and "a RealSense SDK recording has no TF camera poses" in res.output, res.output
    res = CliRunner().invoke(cli, ["info", str(path), "--frames", "--pose-source", "none", "-q"])
    assert res.exit_code == 0 and "3 usable of 3" in res.output, res.output


def test_without_the_colour_extrinsics_colour_is_left_out_with_a_warning(tmp_path):
    path = tmp_path / "no_color_tf.bag"
    write_sdk_bag(path, 0.001, color_tf=False, frames=2)
    frames, stats = _frames(path)
    assert len(frames) == 2 and all(f.color is None for f in frames)
    assert stats.color_registration["mode"] == "none"
    assert f"{COLOR}/tf/<group>" in stats.color_registration["reason"]
    warnings = stats.warnings(str(path))
    assert any("frames without colour" in w and "no extrinsics recorded" in w for w in warnings), warnings


def test_without_depth_units_1_mm_is_assumed_and_said(tmp_path):
    path = tmp_path / "no_units.bag"
    truth = write_sdk_bag(path, None, frames=1)
    frames, stats = _frames(path)
    valid = truth[0][0] > 0
    assert np.abs(frames[0].depth[valid] - truth[0][0][valid]).max() <= 0.0005 + 1e-6
    assert any("1 mm per unit assumed" in n for n in stats.notes), stats.notes


def test_a_colour_lens_in_the_sdk_s_distortion_model_is_projected_through(tmp_path):
    """A D455-like colour camera: its distortion recorded as "Inverse Brown Conrady" (the SDK's name), which the
    generic reader refuses; projected through it, the colour lands where the pinhole colour would."""
    path = tmp_path / "lens.bag"
    D = np.array([-0.25, 0.06, 0.0, 0.0, 0.0])  # (read as pinhole: 7-8 % of the pixels off, 1.3 % through it)
    truth = write_sdk_bag(path, 0.001, frames=2, color_D=D)
    frames, stats = _frames(path)
    assert stats.color_registration["mode"] == "project", stats.color_registration
    for f, (depth, own) in zip(frames, truth):
        seen = f.color_mask
        assert seen[depth > 0].mean() > 0.9
        err = np.abs(f.color.astype(int) - own.astype(int)).max(axis=2)[seen]
        assert np.mean(err > 30) < 0.05, np.mean(err > 30)


def test_fuse_reads_an_sdk_bag_in_metres_with_icp_and_projected_colour(tmp_path):
    path = tmp_path / "arc.bag"
    write_sdk_bag(path, 0.0001, frames=4, span_deg=4.0)
    out = tmp_path / "fused"
    res = CliRunner().invoke(cli, ["fuse", str(path), "-o", str(out), "--voxel-size", "0.02", "--quiet"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    assert report["frames"]["used"] == 4 and report["frames"]["depth_units_m"] == 0.0001
    assert report["frames"]["color_registration"]["mode"] == "project" and report["tracking"]["lost"] == 0
    # the scene (a table about 1 m from the camera) fits a grid of a few metres, not one 10x too far
    assert max(report["grid"]["size_m"]) < 4.0, report["grid"]["size_m"]


def test_images_with_the_sdk_s_appended_depth_units_are_read(tmp_path):
    """Recent librealsense versions append a float32 depth_units to each sensor_msgs/Image (under the standard
    definition): a strict ROS 1 reader refuses them as a size mismatch. Read, with that value as the scale when
    the Depth Units option is not recorded."""
    path = tmp_path / "trailer.bag"
    truth = write_sdk_bag(path, None, frames=2, image_units=0.0001)
    frames, stats = _frames(path)
    assert len(frames) == 2 and stats.depth_units == pytest.approx(0.0001) and not stats.notes
    for f, (depth, own) in zip(frames, truth):
        valid = depth > 0
        assert np.abs(f.depth[valid] - depth[valid]).max() <= 0.00005 + 1e-6
        err = np.abs(f.color.astype(int) - own.astype(int)).max(axis=2)[f.color_mask]
        assert np.mean(err > 30) < 0.05
