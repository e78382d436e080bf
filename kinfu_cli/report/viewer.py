"""The viewer file (the commands' viz option): one MCAP of Foxglove messages holding what a run found, for Foxglove.

Why MCAP + Foxglove (not a Rerun .rrd): the mcap library is already a dependency (no heavy install), ROS users
already record and view MCAP in Foxglove, and the messages use Foxglove's own protobuf schemas (the official
foxglove-schemas-protobuf package), embedded in the file, so any MCAP reader decodes them without kinfu.

`write_viewer(path, fusion=..., pois=..., views=..., segments=..., grid=...)` writes whichever parts it is given
(the results of fuse_recording, detect_pois, rank_poi_views / rank_object_views, segment_volume, and a
TernaryGrid) and returns a summary: topics with their message counts, entity counts and what was decimated.
Topics (frame: the world frame of the results, "world" when unnamed):

- /tf (foxglove.FrameTransform): world -> camera at every fused frame's stamp, world -> hand at every hand sample
- /kinfu/camera_calibration (foxglove.CameraCalibration): the depth intrinsics on the camera frame
- /kinfu/camera_trajectory, /kinfu/hand_trajectory (foxglove.PosesInFrame): the whole paths, one message each
- /kinfu/mesh (foxglove.SceneUpdate, entity "mesh"): the fused mesh, per-vertex colour, decimated above
  max_triangles; /kinfu/cloud (foxglove.PointCloud): the surface cloud, subsampled above max_points
- /kinfu/occupied (foxglove.PointCloud): occupied voxel centres of a grid (nbv, which has no mesh)
- /kinfu/pois (SceneUpdate, entities "poi/ID"): a sphere coloured by saliency, the region sphere, a label
- /kinfu/views (SceneUpdate, entities "view/poiID/RANK" or "view/segmentID/RANK"): each ranked view as a camera
  frustum placed at its pose, coloured green (best) to red by rank; "region/..." the sphere S(POI) ranked around
- /kinfu/segments (foxglove.PointCloud): the surface points coloured by segment (support plane grey)
- /kinfu/superquadrics (SceneUpdate, entities "superquadric/ID"): each fit as a triangle mesh of its surface
- /kinfu/support_plane (SceneUpdate, entity "support_plane"): a thin box over the plane's points

Static content is stamped at the first camera stamp (else the hand trajectory's start, else 0), so a player
shows it from the start while the camera and hand frames move.
"""

from __future__ import annotations

import colorsys
import os
from pathlib import Path
from typing import Any

import numpy as np
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.SpherePrimitive_pb2 import SpherePrimitive
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.report import viewer_messages as fm
from kinfu_cli.segmentation.pipeline import support_plane_points
from kinfu_cli.segmentation.saliency import oriented_box

MAX_TRIANGLES = 300_000  # larger meshes are decimated (quadric decimation): a few tens of MB at most
MAX_POINTS = 500_000  # larger clouds are subsampled (seeded): 16 bytes a point
FRUSTUM_DEPTH_M = 0.12  # how far a view's frustum reaches in the viewer (display only)
POI_MARKER_M = 0.03  # diameter of a POI's marker sphere
PARTS = ("fusion", "pois", "views", "segments", "grid")


class _Out:
    """Messages to write, with per-topic counts (the summary)."""

    def __init__(self) -> None:
        self.messages: list[tuple[str, Any, int]] = []
        self.entities: dict[str, int] = {}
        self.notes: dict[str, Any] = {}

    def add(self, topic: str, msg: Any, ns: int) -> None:
        self.messages.append((topic, msg, int(ns)))

    def scene(self, topic: str, ns: int, entities: list) -> None:
        if entities:
            self.add(topic, SceneUpdate(entities=entities), ns)
            self.entities[topic] = self.entities.get(topic, 0) + len(entities)

    def topics(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for topic, _, _ in self.messages:
            counts[topic] = counts.get(topic, 0) + 1
        return counts


def write_viewer(path: str | os.PathLike, *, fusion=None, pois=None, views=None, segments=None, grid=None,
                 max_triangles: int = MAX_TRIANGLES, max_points: int = MAX_POINTS) -> dict:
    """Write the viewer MCAP at `path` (atomically, recorded in the ownership manifest) from the parts given:
    fusion (FusionResult), pois (PoiDetection), views (PoiViews or ObjectViews), segments (SegmentResult),
    grid (TernaryGrid, drawn as occupied voxels when there is no fusion). Returns the summary dict."""
    from mcap_protobuf.writer import Writer  # the protobuf channel/schema registration of the mcap library

    if all(p is None for p in (fusion, pois, views, segments, grid)):
        raise ConfigError("nothing to draw: give at least one of " + ", ".join(PARTS), parameter="viz")
    frame = _frame_name(fusion, pois, views, segments, grid)
    t0 = _reference_ns(fusion, pois)
    out = _Out()
    if fusion is not None:
        _add_fusion(out, fusion, frame, t0, max_triangles, max_points)
    elif grid is not None:
        _add_occupied(out, grid, frame, t0, max_points)
    if pois is not None:
        _add_pois(out, pois, frame, t0)
    if views is not None:
        _add_views(out, views, frame, t0)
    if segments is not None:
        _add_segments(out, segments, frame, t0, max_points)
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh, Writer(fh) as writer:
            for topic, msg, ns in sorted(out.messages, key=lambda m: m[2]):
                writer.write_message(topic, msg, log_time=ns, publish_time=ns)
    return {"path": str(path), "format": "mcap (foxglove protobuf schemas)", "frame": frame,
            "topics": out.topics(), "entities": out.entities, **out.notes}


def _frame_name(*parts) -> str:
    """The world frame the results are in: the first part that names one, else "world"."""
    fusion, pois, views, segments, grid = parts
    names = [getattr(getattr(fusion, "volume", None), "frame", ""), getattr(getattr(pois, "trajectory", None),
             "frame", ""), getattr(getattr(views, "grid", None), "frame", ""), getattr(grid, "frame", "")]
    return next((n for n in names if n), "world")


def _reference_ns(fusion, pois) -> int:
    if fusion is not None and len(fusion.camera_stamps_ns):
        return int(fusion.camera_stamps_ns[0])
    if pois is not None:
        return int(pois.trajectory.t0_ns)
    return 0


def _add_fusion(out: _Out, fusion, frame: str, t0: int, max_triangles: int, max_points: int) -> None:
    stamps, poses = list(fusion.camera_stamps_ns), np.array(fusion.camera_poses).reshape(-1, 4, 4)
    for ns, T in zip(stamps, poses):
        out.add("/tf", fm.frame_transform(ns, frame, "camera", T), ns)
    if len(poses):
        out.add("/kinfu/camera_trajectory", fm.poses_in_frame(t0, frame, poses=poses), t0)
        if fusion.volume.intrinsics:
            out.add("/kinfu/camera_calibration", fm.camera_calibration(t0, "camera", fusion.volume.intrinsics), t0)
    mesh = fusion.mesh
    if len(mesh.triangles):
        if len(mesh.triangles) > max_triangles:
            out.notes["mesh_decimated"] = {"from": len(mesh.triangles), "to": max_triangles}
            mesh = mesh.simplify_quadric_decimation(max_triangles)
        colors = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else None
        prim = fm.triangle_list(np.asarray(mesh.vertices), np.asarray(mesh.triangles), colors)
        out.scene("/kinfu/mesh", t0, [fm.entity(t0, frame, "mesh", triangles=[prim])])
    pts = np.asarray(fusion.cloud.points)
    if len(pts):
        cols = np.asarray(fusion.cloud.colors) if fusion.cloud.has_colors() else None
        keep = _subsample(len(pts), max_points, out, "cloud_subsampled")
        out.add("/kinfu/cloud", fm.point_cloud(t0, frame, pts[keep], None if cols is None else cols[keep]), t0)


def _subsample(n: int, cap: int, out: _Out, note: str) -> np.ndarray:
    if n <= cap:
        return np.arange(n)
    out.notes[note] = {"from": n, "to": cap}
    return np.sort(np.random.default_rng(0).choice(n, cap, replace=False))


def _add_occupied(out: _Out, grid, frame: str, t0: int, max_points: int) -> None:
    idx = np.argwhere(grid.labels == 1)
    if len(idx):
        keep = _subsample(len(idx), max_points, out, "occupied_subsampled")
        out.add("/kinfu/occupied", fm.point_cloud(t0, frame, grid.centers(idx[keep])), t0)


def _ramp(x: float, alpha: float = 1.0) -> tuple[float, float, float, float]:
    """0 -> green, 1 -> red (through yellow)."""
    x = float(np.clip(x, 0.0, 1.0))
    return (min(1.0, 2 * x), min(1.0, 2 * (1 - x)), 0.1, alpha)


def _add_pois(out: _Out, found, frame: str, t0: int) -> None:
    traj = found.trajectory
    stamps = traj.t0_ns + np.rint(traj.t * 1e9).astype(np.int64)
    rot = traj.rotations if traj.rotations is not None else np.tile(np.eye(3), (len(traj.t), 1, 1))
    T = np.tile(np.eye(4), (len(traj.t), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = rot, traj.positions
    for ns, Ti in zip(stamps, T):
        out.add("/tf", fm.frame_transform(int(ns), frame, "hand", Ti), int(ns))
    out.add("/kinfu/hand_trajectory", fm.poses_in_frame(t0, frame, poses=T), t0)
    sal = np.array([p.saliency for p in found.pois], dtype=np.float64)
    lo, hi = (sal.min(), sal.max()) if len(sal) else (0.0, 1.0)
    entities = []
    for p, s in zip(found.pois, sal):
        level = 1.0 if hi <= lo else (s - lo) / (hi - lo)  # the most salient POI red
        marker = SpherePrimitive(pose=fm.pose(position=p.position), size={"x": POI_MARKER_M, "y": POI_MARKER_M,
                                 "z": POI_MARKER_M}, color=fm.color(_ramp(level)))
        d = 2 * float(p.radius)
        region = SpherePrimitive(pose=fm.pose(position=p.position), size={"x": d, "y": d, "z": d},
                                 color=fm.color(_ramp(level, 0.12)))
        label = TextPrimitive(pose=fm.pose(position=p.position + [0, 0, POI_MARKER_M]), billboard=True,
                              font_size=14, scale_invariant=True, color=fm.color((1, 1, 1, 1)), text=f"POI {p.id}")
        e = fm.entity(t0, frame, f"poi/{p.id}", spheres=[marker, region], texts=[label])
        e.metadata.extend(fm.metadata(saliency=float(s), time_s=float(p.time), radius=float(p.radius),
                                      task=p.extra.get("task", 0)))
        entities.append(e)
    out.scene("/kinfu/pois", t0, entities)


def _add_views(out: _Out, ranked, frame: str, t0: int) -> None:
    doc = ranked.to_json()
    cam = doc["camera"]
    if doc.get("mode") == "objects":
        groups = [] if doc.get("pose") is None else [(f"segment{doc['segment_id']}", doc["region"]["center"],
                                                     doc["region"]["radius"], doc["views"])]
    else:
        groups = [(f"poi{p['id']}", p["position"], p["radius"], p["views"]) for p in doc["pois"]]
    entities = []
    for name, center, radius, views in groups:
        d = 2 * float(radius)
        entities.append(fm.entity(t0, frame, f"region/{name}", spheres=[SpherePrimitive(
            pose=fm.pose(position=center), size={"x": d, "y": d, "z": d}, color=fm.color((0.3, 0.5, 1.0, 0.12)))]))
        for rank, v in enumerate(views, start=1):
            level = 0.0 if len(views) < 2 else (rank - 1) / (len(views) - 1)
            e = fm.entity(t0, frame, f"view/{name}/{rank}",
                          lines=[fm.frustum(v["pose"], cam, FRUSTUM_DEPTH_M, _ramp(level))])
            e.metadata.extend(fm.metadata(rank=rank, gain=v["gain"], target=name))
            entities.append(e)
    out.scene("/kinfu/views", t0, entities)


def label_colors(labels: np.ndarray) -> np.ndarray:
    """(N, 3) colours 0..1: a distinct hue per segment label (golden-ratio steps), the support plane (0) grey,
    noise (< 0) dark."""
    labels = np.asarray(labels)
    hues = (labels * 0.618033988749895) % 1.0
    rgb = np.array([colorsys.hsv_to_rgb(h, 0.75, 0.95) for h in hues]).reshape(-1, 3)
    rgb[labels == 0] = 0.6
    rgb[labels < 0] = 0.2
    return rgb


def _add_segments(out: _Out, result, frame: str, t0: int, max_points: int) -> None:
    seg = result.segmentation
    if len(seg.points):
        keep = _subsample(len(seg.points), max_points, out, "segments_subsampled")
        out.add("/kinfu/segments", fm.point_cloud(t0, frame, seg.points[keep], label_colors(seg.labels[keep])), t0)
    entities = []
    for s in result.saliency:
        fit = result.superquadrics.get(s.id)
        fits = result.multi[s.id].parts if s.id in result.multi else ([fit] if hasattr(fit, "superquadric") else [])
        if not fits:
            continue
        rgba = (*label_colors(np.array([s.id]))[0], 0.5)
        prims = []
        for f in fits:
            sq = f.superquadric
            v, tris = fm.superquadric_surface(sq.size, sq.exponents)
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = sq.rotation, sq.center
            prims.append(fm.triangle_list(v, tris, rgba=rgba, T=T))
        e = fm.entity(t0, frame, f"superquadric/{s.id}", triangles=prims)
        e.metadata.extend(fm.metadata(saliency=s.saliency, residual_m=fits[0].residual, parts=len(fits)))
        entities.append(e)
    out.scene("/kinfu/superquadrics", t0, entities)
    plane_pts = support_plane_points(seg)
    if seg.plane is not None and len(plane_pts) >= 3:
        _add_plane(out, plane_pts, frame, t0)


def _add_plane(out: _Out, pts: np.ndarray, frame: str, t0: int) -> None:
    box = oriented_box(pts)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = box.axes, box.center
    size = np.maximum(box.extents, 0.004)
    cube = CubePrimitive(pose=fm.pose(T), size={"x": size[0], "y": size[1], "z": size[2]},
                         color=fm.color((0.6, 0.6, 0.6, 0.35)))
    out.scene("/kinfu/support_plane", t0, [fm.entity(t0, frame, "support_plane", cubes=[cube])])
