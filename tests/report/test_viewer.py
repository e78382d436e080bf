"""The viewer file (`--viz`, report/viewer.py): an MCAP of Foxglove messages, read back with the mcap library's
reader and Foxglove's own protobuf schemas (foxglove-schemas-protobuf): every message decodes with the official
definition, the schemas in the file are the official ones, poses round-trip and counts match what each command
wrote."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import open3d as o3d
import pytest
from click.testing import CliRunner
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from google.protobuf.message import Message
from google.protobuf.unknown_fields import UnknownFieldSet
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from scipy.spatial.transform import Rotation

import foxglove_schemas_protobuf.CameraCalibration_pb2 as cal_pb2
import foxglove_schemas_protobuf.FrameTransform_pb2 as tf_pb2
import foxglove_schemas_protobuf.PointCloud_pb2 as pc_pb2
import foxglove_schemas_protobuf.PosesInFrame_pb2 as pif_pb2
import foxglove_schemas_protobuf.SceneUpdate_pb2 as su_pb2
from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.tum import read_tum
from kinfu_cli.report.viewer import write_viewer
from kinfu_cli.report.viewer_messages import frustum_points, superquadric_surface
from kinfu_cli.segmentation.superquadric import inside_outside_local

OFFICIAL = {m.DESCRIPTOR.full_name: m for m in (cal_pb2.CameraCalibration, tf_pb2.FrameTransform,
                                               pc_pb2.PointCloud, pif_pb2.PosesInFrame, su_pb2.SceneUpdate)}
INTRINSICS = {"fx": 525.0, "fy": 520.0, "cx": 319.5, "cy": 239.5, "width": 640, "height": 480}


def read_viewer(path) -> list[tuple[str, str, Message]]:
    """(topic, schema name, message) of every message, decoded by the mcap reader from the schemas in the file,
    after checking each against Foxglove's own definition (see check_official)."""
    out = []
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for schema, channel, raw, decoded in reader.iter_decoded_messages(log_time_order=True):
            assert channel.message_encoding == "protobuf" and schema.encoding == "protobuf"
            check_official(schema, raw.data, decoded)
            out.append((channel.topic, schema.name, decoded))
    return out


def check_official(schema, data: bytes, decoded) -> None:
    """The schema is Foxglove's official one, the message parses with the official class with no unknown field,
    and its content is well formed for Foxglove's 3D panel (unit quaternions, colours in 0..1, whole points,
    indices in range)."""
    official = OFFICIAL[schema.name]
    fds = FileDescriptorSet.FromString(schema.data)
    files = {f.name: f for f in fds.file}
    want = official.DESCRIPTOR.file
    assert files[want.name].SerializeToString(deterministic=True) == \
        _proto_of(want).SerializeToString(deterministic=True)
    msg = official.FromString(data)
    _no_unknown(msg)
    assert msg.SerializeToString(deterministic=True) == decoded.SerializeToString(deterministic=True)
    _well_formed(msg)


def _proto_of(file_descriptor):
    from google.protobuf.descriptor_pb2 import FileDescriptorProto

    p = FileDescriptorProto()
    file_descriptor.CopyToProto(p)
    return p


def _no_unknown(msg: Message) -> None:
    assert len(UnknownFieldSet(msg)) == 0
    for field, value in msg.ListFields():
        if field.message_type is None:
            continue
        for v in (value if field.is_repeated else [value]):
            _no_unknown(v)


def _well_formed(msg: Message) -> None:
    for field, value in msg.ListFields():
        items = value if field.is_repeated else [value]
        if field.message_type is None:
            continue
        name = field.message_type.full_name
        for v in items:
            if name == "foxglove.Quaternion":
                assert abs(np.linalg.norm([v.x, v.y, v.z, v.w]) - 1) < 1e-9
            elif name == "foxglove.Color":
                assert all(0 <= c <= 1 for c in (v.r, v.g, v.b, v.a))
            elif name == "foxglove.PointCloud":
                assert len(v.data) % v.point_stride == 0 and all(f.offset < v.point_stride for f in v.fields)
            elif name == "foxglove.TriangleListPrimitive":
                assert len(v.indices) % 3 == 0 and max(v.indices, default=0) < len(v.points)
                assert len(v.colors) in (0, len(v.points))
            elif name == "foxglove.LinePrimitive" and v.type == v.LINE_LIST:
                assert len(v.points) % 2 == 0
            _well_formed(v)


def pose_matrix(p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]).as_matrix()
    T[:3, 3] = [p.position.x, p.position.y, p.position.z]
    return T


def cloud_xyz(msg) -> np.ndarray:
    dt = np.dtype([("xyz", "<f4", (3,)), ("rgba", "u1", (4,))])
    assert msg.point_stride == dt.itemsize
    return np.frombuffer(msg.data, dtype=dt)["xyz"].astype(np.float64)


def entities(msgs, topic):
    return [e for t, _, m in msgs if t == topic for e in m.entities]


def _fake_fusion(n=6, frame="odom"):
    rng = np.random.default_rng(1)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=2).as_matrix()
    T[:, :3, 3] = rng.uniform(-2, 2, (n, 3))
    mesh = o3d.geometry.TriangleMesh.create_sphere(0.1, resolution=20)
    mesh.vertex_colors = o3d.utility.Vector3dVector(rng.uniform(0, 1, (len(mesh.vertices), 3)))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.uniform(-1, 1, (500, 3))))
    stamps = [1_767_225_600_000_000_000 + i * 200_000_000 for i in range(n)]
    return SimpleNamespace(camera_stamps_ns=stamps, camera_poses=list(T), mesh=mesh, cloud=cloud,
                           volume=SimpleNamespace(frame=frame, intrinsics=INTRINSICS))


def test_camera_poses_mesh_and_cloud_round_trip(tmp_path):
    fusion = _fake_fusion()
    summary = write_viewer(tmp_path / "v.mcap", fusion=fusion)
    msgs = read_viewer(tmp_path / "v.mcap")
    tfs = [m for t, _, m in msgs if t == "/tf"]
    assert len(tfs) == 6 and summary["topics"]["/tf"] == 6 and summary["frame"] == "odom"
    for m, ns, T in zip(tfs, fusion.camera_stamps_ns, fusion.camera_poses):
        assert m.timestamp.ToNanoseconds() == ns and m.parent_frame_id == "odom" and m.child_frame_id == "camera"
        R = Rotation.from_quat([m.rotation.x, m.rotation.y, m.rotation.z, m.rotation.w]).as_matrix()
        assert np.abs(R - T[:3, :3]).max() < 1e-6
        assert np.abs([m.translation.x - T[0, 3], m.translation.y - T[1, 3], m.translation.z - T[2, 3]]).max() < 1e-6
    (path,) = [m for t, _, m in msgs if t == "/kinfu/camera_trajectory"]
    assert np.abs(np.array([pose_matrix(p) for p in path.poses]) - np.array(fusion.camera_poses)).max() < 1e-6
    (cal,) = [m for t, _, m in msgs if t == "/kinfu/camera_calibration"]
    assert cal.frame_id == "camera" and list(cal.K) == [525, 0, 319.5, 0, 520, 239.5, 0, 0, 1]
    (mesh,) = entities(msgs, "/kinfu/mesh")
    tri = mesh.triangles[0]
    assert len(tri.indices) == 3 * len(fusion.mesh.triangles) and len(tri.colors) == len(fusion.mesh.vertices)
    v = np.array([[p.x, p.y, p.z] for p in tri.points])
    assert np.abs(v - np.asarray(fusion.mesh.vertices)).max() < 1e-12
    (cloud,) = [m for t, _, m in msgs if t == "/kinfu/cloud"]
    assert np.abs(cloud_xyz(cloud) - np.asarray(fusion.cloud.points)).max() < 1e-6


def test_large_mesh_is_decimated_and_cloud_subsampled(tmp_path):
    fusion = _fake_fusion()
    summary = write_viewer(tmp_path / "v.mcap", fusion=fusion, max_triangles=200, max_points=100)
    assert summary["mesh_decimated"] == {"from": len(fusion.mesh.triangles), "to": 200}
    assert summary["cloud_subsampled"] == {"from": 500, "to": 100}
    msgs = read_viewer(tmp_path / "v.mcap")
    (mesh,) = entities(msgs, "/kinfu/mesh")
    assert 0 < len(mesh.triangles[0].indices) // 3 <= 200
    (cloud,) = [m for t, _, m in msgs if t == "/kinfu/cloud"]
    xyz = cloud_xyz(cloud)
    assert len(xyz) == 100 and np.isin(xyz.round(5), np.asarray(fusion.cloud.points).round(5)).all()


@pytest.mark.parametrize("exponents", [(1.0, 1.0), (0.2, 0.3), (1.8, 0.6)])
def test_superquadric_surface_lies_on_the_superquadric(exponents):
    size = np.array([0.05, 0.03, 0.08])
    v, tris = superquadric_surface(size, exponents, n_lat=12, n_lon=24)
    away = np.linalg.norm(v[:, :2], axis=1) > 1e-9  # the poles: F is exact there too but the log form clamps
    F = inside_outside_local(v[away], size, np.array(exponents))
    assert np.abs(F - 1).max() < 1e-6
    assert len(tris) == 2 * 12 * 24 and tris.max() < len(v)
    assert np.allclose(np.abs(v).max(axis=0), size)


def test_frustum_far_corners_project_to_the_image_corners():
    pts = frustum_points(INTRINSICS, 0.12)
    assert pts.shape == (16, 3) and np.all(pts[0::4][:2] == 0)
    far = pts[1:8:2]
    K = np.array([[525, 0, 319.5], [0, 520, 239.5], [0, 0, 1]])
    uv = (far @ K.T)[:, :2] / far[:, 2:]
    assert np.allclose(far[:, 2], 0.12) and np.allclose(uv, [[0, 0], [640, 0], [640, 480], [0, 480]])


def test_nothing_to_draw_is_an_error(tmp_path):
    with pytest.raises(ConfigError, match="nothing to draw"):
        write_viewer(tmp_path / "v.mcap")
    assert not (tmp_path / "v.mcap").exists()


# ---- each command's --viz, on the bundled sample (one pipeline run for all the checks) ----

def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def pipeline(sample_dir, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("viz")
    rec = sample_dir / "recording.mcap"
    steps = [
        ("fuse", rec, "-o", tmp / "fuse", "--end", "6", "--every", "2", "--voxel-size", "0.01", "--viz", tmp / "fuse.mcap"),
        ("poi", rec, "-o", tmp / "pois.json", "--viz", tmp / "poi.mcap"),
        ("nbv", tmp / "fuse" / "volume.npz", "--pois", tmp / "pois.json", "--clear", "-o", tmp / "views.json",
         "--lon-step", "60", "--roll-step", "90", "--top", "4", "--viz", tmp / "nbv.mcap"),
        ("segment", tmp / "fuse" / "volume.npz", "-o", tmp / "seg", "--viz", tmp / "seg.mcap"),
    ]
    for step in steps:
        res = run(*step, "--quiet")
        assert res.exit_code == 0, (step[0], res.output)
    return tmp


@pytest.mark.slow
def test_fuse_viz_holds_the_trajectory_it_fused(pipeline):
    msgs = read_viewer(pipeline / "fuse.mcap")
    report = json.loads((pipeline / "fuse" / "report.json").read_text())
    stamps, poses = read_tum(pipeline / "fuse" / "trajectory.tum")
    tfs = [m for t, _, m in msgs if t == "/tf"]
    assert len(tfs) == len(poses) == report["frames"]["used"] > 10
    assert [m.timestamp.ToNanoseconds() for m in tfs] == stamps.tolist()
    (path,) = [m for t, _, m in msgs if t == "/kinfu/camera_trajectory"]
    assert np.abs(np.array([pose_matrix(p) for p in path.poses]) - poses).max() < 1e-6
    (mesh,) = entities(msgs, "/kinfu/mesh")
    assert len(mesh.triangles[0].indices) // 3 == report["mesh"]["triangles"]
    (cloud,) = [m for t, _, m in msgs if t == "/kinfu/cloud"]
    assert len(cloud_xyz(cloud)) == report["cloud"]["points"]


@pytest.mark.slow
def test_poi_viz_holds_the_hand_trajectory_and_every_poi(pipeline):
    msgs = read_viewer(pipeline / "poi.mcap")
    doc = json.loads((pipeline / "pois.json").read_text())
    pois = entities(msgs, "/kinfu/pois")
    assert sorted(e.id for e in pois) == sorted(f"poi/{p['id']}" for p in doc["pois"]) and len(pois) >= 1
    for e, p in zip(sorted(pois, key=lambda e: e.id), sorted(doc["pois"], key=lambda p: f"poi/{p['id']}")):
        c = e.spheres[0].pose.position
        assert np.abs(np.array([c.x, c.y, c.z]) - p["position"]).max() < 1e-9
        assert e.spheres[1].size.x == pytest.approx(2 * p["radius"])
        assert float(dict((kv.key, kv.value) for kv in e.metadata)["saliency"]) == pytest.approx(p["saliency"])
    (hand,) = [m for t, _, m in msgs if t == "/kinfu/hand_trajectory"]
    hand_tf = [m for t, _, m in msgs if t == "/tf"]
    assert len(hand.poses) == len(hand_tf) > 100 and {m.child_frame_id for m in hand_tf} == {"hand"}


@pytest.mark.slow
def test_nbv_viz_has_one_frustum_per_view_written_at_its_pose(pipeline):
    msgs = read_viewer(pipeline / "nbv.mcap")
    doc = json.loads((pipeline / "views.json").read_text())
    views = {e.id: e for e in entities(msgs, "/kinfu/views") if e.id.startswith("view/")}
    written = {f"view/poi{p['id']}/{r}": v for p in doc["pois"] for r, v in enumerate(p["views"], start=1)}
    assert set(views) == set(written) and len(written) == 4 * len(doc["pois"])
    for key, v in written.items():
        (line,) = views[key].lines
        assert np.abs(pose_matrix(line.pose) - np.array(v["pose"])).max() < 1e-6
        assert len(line.points) == 16
    assert [m for t, _, m in msgs if t == "/kinfu/occupied"]


@pytest.mark.slow
def test_segment_viz_has_each_superquadric_and_the_plane(pipeline):
    msgs = read_viewer(pipeline / "seg.mcap")
    doc = json.loads((pipeline / "seg" / "segments.json").read_text())
    fitted = {s["id"]: s["superquadric"] for s in doc["segments"] if s["superquadric"]}
    sqs = {e.id: e for e in entities(msgs, "/kinfu/superquadrics")}
    assert set(sqs) == {f"superquadric/{i}" for i in fitted} and fitted
    for i, sq in fitted.items():
        (tri,) = sqs[f"superquadric/{i}"].triangles
        T = pose_matrix(tri.pose)
        assert np.abs(T[:3, 3] - sq["center"]).max() < 1e-6 and np.abs(T[:3, :3] - np.array(sq["rotation"])).max() < 1e-6
        local = np.array([[p.x, p.y, p.z] for p in tri.points])
        local = local[np.linalg.norm(local[:, :2], axis=1) > 1e-9]
        assert np.abs(inside_outside_local(local, np.array(sq["size"]), np.array(sq["exponents"])) - 1).max() < 1e-6
    (seg_cloud,) = [m for t, _, m in msgs if t == "/kinfu/segments"]
    assert len(cloud_xyz(seg_cloud)) == doc["points"]
    assert (len(entities(msgs, "/kinfu/support_plane")) == 1) == (doc["support_plane"] is not None)


def test_viz_obeys_the_output_rules(sample_dir, tmp_path):
    """A file kinfu did not write is refused before any work (one line naming --viz), kept unchanged."""
    foreign = tmp_path / "mine.mcap"
    foreign.write_text("not kinfu's")
    one_line_error(run("poi", sample_dir / "recording.mcap", "-o", tmp_path / "p.json", "--viz", foreign), "--viz")
    assert foreign.read_text() == "not kinfu's" and not (tmp_path / "p.json").exists()
    one_line_error(run("poi", sample_dir / "recording.mcap", "-o", tmp_path / "p.json",
                       "--viz", sample_dir / "recording.mcap", "--force"), "--viz")
