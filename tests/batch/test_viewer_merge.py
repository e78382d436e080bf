"""One viewer file per recording (`kinfu batch --viz`): the stages' viewer files combined, read back with the
mcap reader and Foxglove's own classes; unclocked content moved to the others' time, the occupied cloud dropped
when the mesh is there."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import open3d as o3d
import pytest
from mcap.reader import make_reader

import foxglove_schemas_protobuf.PointCloud_pb2 as pc_pb2
import foxglove_schemas_protobuf.SceneUpdate_pb2 as su_pb2
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.core.ownership import written_by_kinfu
from kinfu_cli.report.viewer import write_viewer
from kinfu_cli.report.viewer_merge import merge_viewers

T0 = 1_767_225_600_000_000_000
OFFICIAL = {"foxglove.PointCloud": pc_pb2.PointCloud, "foxglove.SceneUpdate": su_pb2.SceneUpdate}


def read(path) -> list[tuple[str, int, object]]:
    """(topic, log time, message) with the official class when it is a cloud or a scene update."""
    out = []
    with open(path, "rb") as fh:
        for schema, channel, m in make_reader(fh).iter_messages(log_time_order=True):
            assert schema.encoding == "protobuf" and schema.name.startswith("foxglove.")
            cls = OFFICIAL.get(schema.name)
            out.append((channel.topic, m.log_time, cls.FromString(m.data) if cls else None))
    return out


def _fusion():
    mesh = o3d.geometry.TriangleMesh.create_box(0.2, 0.2, 0.2)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.random.default_rng(0).uniform(0, 1, (50, 3))))
    poses = [np.eye(4) for _ in range(3)]
    return SimpleNamespace(camera_stamps_ns=[T0 + i * 10**8 for i in range(3)], camera_poses=poses, mesh=mesh,
                           cloud=cloud, volume=SimpleNamespace(frame="map", intrinsics=None))


def _pois():
    t = np.linspace(0, 2, 21)
    traj = SimpleNamespace(t=t, positions=np.c_[t, t, t], rotations=None, t0_ns=T0 + 5 * 10**8, frame="map")
    poi = SimpleNamespace(id=0, position=np.array([1.0, 1.0, 1.0]), saliency=1.0, radius=0.2, time=1.0, extra={})
    return SimpleNamespace(trajectory=traj, pois=[poi])


def _grid():
    labels = np.zeros((4, 4, 4), np.int8)
    labels[1:3, 1:3, 1] = 1
    return TernaryGrid(labels=labels, origin=np.zeros(3), voxel_size=0.1, frame="map")


def test_parts_are_combined_on_one_clock(tmp_path):
    fuse, pois, views = tmp_path / "fuse.mcap", tmp_path / "pois.mcap", tmp_path / "views.mcap"
    write_viewer(fuse, fusion=_fusion())
    write_viewer(pois, pois=_pois())
    write_viewer(views, grid=_grid())  # nbv draws its grid when it has no mesh, stamped 0: it has no clock
    assert {t for t, ns, _ in read(views)} == {"/kinfu/occupied"} and {ns for _, ns, _ in read(views)} == {0}
    parts = {p: read(p) for p in (fuse, pois)}
    summary = merge_viewers(tmp_path / "all.mcap", [fuse, pois, views])
    merged = read(tmp_path / "all.mcap")
    assert written_by_kinfu(tmp_path / "all.mcap")
    # every message of the clocked parts, at its time; the occupied cloud dropped beside the fused surface
    assert sorted((t, ns) for t, ns, _ in merged) == sorted((t, ns) for p in parts.values() for t, ns, _ in p)
    assert summary["dropped_occupied"] and summary["frames"] == ["map"]
    assert summary["topics"]["/tf"] == 3 + 21  # the camera at every fused frame, the hand at every sample

    # without the mesh the occupied cloud stays, moved to the first clocked stamp (the hand's start), inside too
    summary = merge_viewers(tmp_path / "two.mcap", [pois, views])
    merged = read(tmp_path / "two.mcap")
    assert min(ns for _, ns, _ in merged) == T0 + 5 * 10**8 and summary["restamped"] == 1
    (occ,) = [m for t, _, m in merged if t == "/kinfu/occupied"]
    assert occ.timestamp.ToNanoseconds() == T0 + 5 * 10**8 and len(occ.data) == 4 * occ.point_stride


def test_a_bad_part_is_one_line(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap")
    with pytest.raises(ConfigError, match="bad.mcap: not a readable viewer file"):
        merge_viewers(tmp_path / "all.mcap", [bad])
    assert not (tmp_path / "all.mcap").exists()
