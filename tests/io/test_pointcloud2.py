"""A recording holding only the camera driver's organized PointCloud2 (no depth images) fuses like its depth images:
z per pixel is the depth, the rgb field the colour, and the intrinsics come from a camera info in the cloud's frame
or are recovered from the cloud itself. An unorganized cloud is refused, saying so."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.pointcloud2 import decode_cloud, fit_intrinsics, organized_cloud
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles
from kinfu_cli.io.writers import RecordingWriter
from kinfu_cli.sim.paths import orbit_poses
from kinfu_cli.sim.scene import primitive_tabletop_scene
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

S = 1_000_000_000
W, H = 160, 120
K = kinect_v1_intrinsics(W, H)
FRAME = "camera_depth_optical_frame"
CLOUD = "/camera/depth_registered/points"
WATERCAN = Path(__file__).resolve().parents[3] / "shared" / "data" / "ros-recordings" / "watercan.bag"


@pytest.fixture(scope="module")
def rendered():
    """Four noise-free views of the tabletop: (pose, depth float32 m, colour uint8)."""
    scene = primitive_tabletop_scene(seed=4)
    sensor = DepthSensor(K, W, H, noise=False)
    poses = orbit_poses(4, radius=0.85, height=1.3, target=(0.0, 0.0, 0.75), start_deg=30.0, span_deg=60.0)
    out = []
    for T in poses:
        depth, rgb = sensor.render(scene, T)
        out.append((T, depth.astype(np.float32), rgb))
    return out


def _write(path: Path, views, kind: str, info: bool = True, color: bool = True, **cloud_kw) -> Path:
    """A recording of the views: depth as 32FC1 images (+ rgb8 colour) or as organized clouds (rgb field)."""
    with RecordingWriter(path) as w:
        for i, (T, depth, rgb) in enumerate(views):
            t = S + i * S // 10
            w.write_tf(t, [("world", FRAME, T)])
            if kind == "image":
                w.write_image("/camera/depth/image_rect", t, FRAME, depth, "32FC1")
                if color:
                    w.write_image("/camera/rgb/image_rect_color", t, FRAME, rgb, "rgb8")
            else:
                w.write_pointcloud2(CLOUD, t, FRAME, organized_cloud(depth, K, rgb if color else None, **cloud_kw))
            if info:
                w.write_camera_info("/camera/depth/camera_info", t, FRAME, K, W, H)
    return path


def _fuse(rec: Path, out: Path, *extra: str) -> dict:
    res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(out), "--voxel-size", "0.01", "--size", "1.2",
                                   "--origin", "-0.6,-0.6,0.2", "--quiet", "--fill-gaps", "0", *extra])
    assert res.exit_code == 0, res.output
    return json.loads((out / "report.json").read_text())


def test_cloud_fuses_like_its_depth_images(rendered, tmp_path):
    images = _fuse(_write(tmp_path / "images.mcap", rendered, "image"), tmp_path / "fi")
    with_info = _fuse(_write(tmp_path / "cloud.bag", rendered, "cloud"), tmp_path / "fc")
    recovered = _fuse(_write(tmp_path / "cloud.mcap", rendered, "cloud", info=False), tmp_path / "fr")
    assert with_info["roles"]["depth_topic"] == CLOUD and with_info["frames"]["used"] == len(rendered)
    assert with_info["counts"] == images["counts"]  # the same depth, the same K: the same volume
    for key in ("occupied", "empty"):  # recovered K differs by float rounding: a voxel here or there
        assert abs(recovered["counts"][key] - images["counts"][key]) <= 1e-3 * images["counts"][key]
    a, b = (np.load(tmp_path / d / "ternary.npz")["ternary"] for d in ("fi", "fc"))
    assert np.array_equal(a, b)
    # colour from the rgb field reaches the mesh as the colour image's does
    assert with_info["frames"]["without_color"] == 0 and images["frames"]["without_color"] == 0
    assert not any("recovered" in w for w in with_info["warnings"])


def test_intrinsics_recovered_and_said(rendered, tmp_path):
    rec = _write(tmp_path / "cloud.mcap", rendered, "cloud", info=False)
    stats = FrameStats()
    with open_recording(rec) as r:
        roles = detect_roles(r)
        assert roles.depth_topic == CLOUD and roles.info_topic is None and roles.color_topic is None
        frames = list(iter_frames(r, roles, stats=stats))
    assert len(frames) == len(rendered)
    np.testing.assert_allclose(frames[0].K, K, rtol=1e-3, atol=0)
    assert any("recovered from the cloud" in n and CLOUD in n for n in stats.notes), stats.notes
    report = _fuse(rec, tmp_path / "f")
    assert any("recovered from the cloud" in w for w in report["warnings"]), report["warnings"]
    assert report["intrinsics"]["fx"] == pytest.approx(K[0, 0], rel=1e-3)
    res = CliRunner().invoke(cli, ["info", str(rec)])
    assert res.exit_code == 0 and f"depth topic:    {CLOUD}" in res.output, res.output
    assert "recovered from the cloud" in res.output, res.output
    res = CliRunner().invoke(cli, ["info", str(rec), "--frames", "-q"])
    assert res.exit_code == 0 and f"{len(rendered)} usable of {len(rendered)}" in res.output, res.output
    assert "recovered from the cloud" in res.output


def test_rgb_field_is_the_colour_and_export_writes_depth(rendered, tmp_path):
    rec = _write(tmp_path / "cloud.bag", rendered, "cloud", info=False)
    with open_recording(rec) as r:
        frames = list(iter_frames(r))
    for f, (_, depth, rgb) in zip(frames, rendered):
        assert np.array_equal(f.color, rgb) and np.array_equal(f.depth, depth)
    out = tmp_path / "exported"
    res = CliRunner().invoke(cli, ["export", str(rec), "-o", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    import cv2

    mm = cv2.imread(str(out / "frame-000000.depth.png"), cv2.IMREAD_UNCHANGED)
    assert mm.dtype == np.uint16 and np.array_equal(mm, np.rint(rendered[0][1] * 1000).astype(np.uint16))
    assert np.array_equal(cv2.imread(str(out / "frame-000000.color.png"))[:, :, ::-1], rendered[0][2])


@pytest.mark.parametrize("layout", [dict(float_type="f8"), dict(byteorder=">"), dict(pad=12),
                                    dict(float_type="f8", byteorder=">", pad=3)])
def test_layouts_decode_the_same(rendered, tmp_path, layout):
    _, depth, rgb = rendered[0]
    ref = _write(tmp_path / "ref.mcap", rendered[:1], "cloud", info=False)
    rec = _write(tmp_path / "lay.bag", rendered[:1], "cloud", info=False, **layout)
    with open_recording(ref) as r:
        want = decode_cloud(r.first_message(CLOUD))
    with open_recording(rec) as r:
        msg = r.first_message(CLOUD)
        got = decode_cloud(msg)
        (fx, fy, cx, cy), rms = fit_intrinsics(msg)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[0], depth)
    assert np.array_equal(got[1], rgb) and rms < 1e-3
    np.testing.assert_allclose([fx, fy, cx, cy], [K[0, 0], K[1, 1], K[0, 2], K[1, 2]], rtol=1e-3)


def test_row_padding_decodes_the_same(rendered, tmp_path):
    path = tmp_path / "rows.mcap"
    _, depth, rgb = rendered[0]
    with RecordingWriter(path) as w:
        w.write_pointcloud2(CLOUD, S, FRAME, organized_cloud(depth, K, rgb, byteorder=">"), row_pad=13)
    with open_recording(path) as r:
        got_depth, got_rgb = decode_cloud(r.first_message(CLOUD))
    assert np.array_equal(got_depth, depth) and np.array_equal(got_rgb, rgb)


def test_a_transformed_cloud_is_refused(rendered, tmp_path):
    """A cloud moved into another frame is no pinhole projection of its pixels: one line naming the topic."""
    T, depth, rgb = rendered[0]
    cloud = organized_cloud(depth, K, rgb)
    pts = np.stack([cloud[n].astype(np.float64) for n in "xyz"], axis=-1) @ T[:3, :3].T + T[:3, 3]
    for i, n in enumerate("xyz"):
        cloud[n] = pts[..., i]
    path = tmp_path / "moved.mcap"
    with RecordingWriter(path) as w:
        w.write_pointcloud2(CLOUD, S, FRAME, cloud)
    line = one_line_error(CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "o"), "--quiet",
                                                   "--pose", "icp"]), CLOUD, "pinhole")
    assert "px RMS" in line


def test_unorganized_cloud_only_is_refused(rendered, tmp_path):
    _, depth, rgb = rendered[0]
    flat = organized_cloud(depth, K, rgb).reshape(1, -1)
    flat = flat[:, np.isfinite(flat["z"][0])]
    path = tmp_path / "cluster.mcap"
    with RecordingWriter(path) as w:
        w.write_pointcloud2("/cluster/output", S, "base_link", flat)
    line = one_line_error(CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "o"), "--quiet"]),
                          "/cluster/output", "unorganized", "height 1")
    assert "organized cloud" in line
    one_line_error(CliRunner().invoke(cli, ["fuse", str(path), "-o", str(tmp_path / "o"), "--quiet",
                                            "--depth-topic", "/cluster/output"]), "/cluster/output", "unorganized")
    with open_recording(path) as r, pytest.raises(RecordingError, match="unorganized"):
        list(iter_frames(r, pose_source="none"))


@pytest.mark.skipif(not WATERCAN.exists(), reason="shared data not present")
def test_watercan_bag_says_unorganized(tmp_path):
    line = one_line_error(CliRunner().invoke(cli, ["fuse", str(WATERCAN), "-o", str(tmp_path / "o"), "--quiet"]),
                          "/euclidean_cluster_indices_decomposer/output00", "unorganized")
    assert "height 1" in line
    res = CliRunner().invoke(cli, ["info", str(WATERCAN)])
    assert res.exit_code == 0 and "output00: not a depth source: it is an unorganized" in res.output, res.output


def test_image_preferred_cloud_named_and_foreign_camera_info_unused(rendered, tmp_path):
    """Both an image and a cloud: the image is the depth unless the cloud is named; a camera info in another
    frame (the IR camera's, for a depth_registered cloud) is not the cloud's: its intrinsics are recovered."""
    path = tmp_path / "both.mcap"
    wrong = K.copy()
    wrong[0, 0] *= 1.1
    with RecordingWriter(path) as w:
        for i, (T, depth, rgb) in enumerate(rendered[:2]):
            t = S + i * S // 10
            w.write_tf(t, [("world", FRAME, T), ("world", "ir_frame", T)])
            w.write_image("/camera/depth/image_rect", t, FRAME, depth, "32FC1")
            w.write_pointcloud2(CLOUD, t, FRAME, organized_cloud(depth, K, rgb))
            w.write_camera_info("/camera/depth_registered/camera_info", t, "ir_frame", wrong, W, H)
    with open_recording(path) as r:
        assert detect_roles(r).depth_topic == "/camera/depth/image_rect"
        roles = detect_roles(r, depth_topic=CLOUD)
        assert roles.info_topic is None and roles.color_topic is None
        stats = FrameStats()
        frames = list(iter_frames(r, roles, stats=stats))
    np.testing.assert_allclose(frames[0].K, K, rtol=1e-3)
    assert np.array_equal(frames[1].color, rendered[1][2]) and "recovered from the cloud" in stats.notes[0]


def test_camera_info_that_misses_the_points_gives_way(rendered, tmp_path):
    """A camera info in the cloud's frame whose K does not project the points onto their pixels (P vs K of a
    rectified stream, another resolution mode) is not used: K is recovered, and the note says why."""
    wrong = K.copy()
    wrong[0, 2] += 3.0
    path = tmp_path / "off.bag"
    with RecordingWriter(path) as w:
        T, depth, rgb = rendered[0]
        w.write_pointcloud2(CLOUD, S, FRAME, organized_cloud(depth, K, rgb))
        w.write_camera_info("/camera/depth_registered/camera_info", S, FRAME, wrong, W, H)
    stats = FrameStats()
    with open_recording(path) as r:
        roles = detect_roles(r)
        assert roles.info_topic == "/camera/depth_registered/camera_info"
        frames = list(iter_frames(r, roles, stats=stats, pose_source="none"))
    np.testing.assert_allclose(frames[0].K, K, rtol=1e-3)
    assert "misses its points by 3 px RMS" in stats.notes[0], stats.notes


def test_ros1_encoded_mcap_cloud_reads_like_the_bag(rendered, tmp_path):
    """`mcap convert` of a .bag: the mcap-ros1 decoder's message objects (bytes data) decode alike."""
    from mcap.writer import Writer as McapWriter
    from rosbags.highlevel import AnyReader

    bag = _write(tmp_path / "c.bag", rendered[:2], "cloud", info=False, float_type="f8", byteorder=">", pad=5)
    mcap = tmp_path / "c1.mcap"
    with AnyReader([bag]) as reader, open(mcap, "wb") as f:  # the raw ROS 1 messages, as `mcap convert` keeps them
        w = McapWriter(f)
        w.start(profile="ros1")
        channels = {}
        for conn in reader.connections:
            schema = w.register_schema(name=conn.msgtype.replace("/msg/", "/"), encoding="ros1msg",
                                       data=conn.msgdef.data.encode())
            channels[conn.id] = w.register_channel(topic=conn.topic, message_encoding="ros1", schema_id=schema)
        for conn, stamp, raw in reader.messages():
            w.add_message(channel_id=channels[conn.id], log_time=stamp, publish_time=stamp, data=bytes(raw))
        w.finish()
    with open_recording(bag) as a, open_recording(mcap) as b:
        fa, fb = list(iter_frames(a)), list(iter_frames(b))
    assert len(fa) == len(fb) == 2
    for x, y, (_, depth, rgb) in zip(fa, fb, rendered):
        assert np.array_equal(y.depth, depth) and np.array_equal(y.color, rgb) and np.array_equal(x.K, y.K)


def test_malformed_clouds_raise_recording_errors_only():
    """Hand-made or damaged messages (sizes that do not match the data, fields missing, overlapping or out of
    the point, odd datatypes) are RecordingErrors naming the topic, in decoding and in the intrinsics fit."""
    from types import SimpleNamespace

    from kinfu_cli.core.errors import RecordingError
    from kinfu_cli.io.pointcloud2 import decode_cloud, fit_intrinsics, organized_cloud

    K = np.array([[100.0, 0, 15.5], [0, 100.0, 11.5], [0, 0, 1]])
    arr = organized_cloud(np.full((24, 32), 1.0), K, np.zeros((24, 32, 3), np.uint8))

    def field(name, offset, datatype):
        return SimpleNamespace(name=name, offset=offset, datatype=datatype, count=1)
    xyz = [field("x", 0, 7), field("y", 4, 7), field("z", 8, 7)]
    base = dict(height=24, width=32, point_step=arr.dtype.itemsize, row_step=arr.dtype.itemsize * 32,
                is_bigendian=False, is_dense=False, fields=[*xyz, field("rgb", 16, 7)], data=arr.tobytes())
    changes = [("height", v) for v in (0, -1, 1, 10 ** 9)] + [("width", v) for v in (0, -5, 10 ** 9)]
    changes += [("point_step", v) for v in (0, -4, 4, 10 ** 9)] + [("row_step", v) for v in (0, -1, 10 ** 12)]
    changes += [("data", b""), ("data", bytes(10))]
    changes += [("fields", f) for f in ([], xyz[:1], [field(n, 0, 7) for n in "xyz"], [field("x", -4, 7), *xyz[1:]],
                                        [field("x", 0, 99), *xyz[1:]], [*xyz, field("rgb", 16, 2)],
                                        [*xyz, field("rgb", 30, 7)])]
    for key, value in changes:
        msg = SimpleNamespace(**{**base, key: value})
        for read in (decode_cloud, fit_intrinsics):
            try:
                read(msg, "/cloud")
            except RecordingError as exc:
                assert "/cloud" in str(exc)
