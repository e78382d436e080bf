"""Foxglove messages (the official protobuf schemas of foxglove-schemas-protobuf) from kinfu's arrays.

Builders only: poses, point clouds, triangle lists, camera frusta and superquadric surfaces as the messages
Foxglove's 3D panel draws; `report.viewer` decides what goes on which topic.
"""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.TriangleListPrimitive_pb2 import TriangleListPrimitive
from google.protobuf.timestamp_pb2 import Timestamp

from kinfu_cli.core.poses import matrix_to_quaternion

_POINT_FIELDS = (("x", 0, PackedElementField.FLOAT32), ("y", 4, PackedElementField.FLOAT32),
                 ("z", 8, PackedElementField.FLOAT32), ("red", 12, PackedElementField.UINT8),
                 ("green", 13, PackedElementField.UINT8), ("blue", 14, PackedElementField.UINT8),
                 ("alpha", 15, PackedElementField.UINT8))
_POINT_DTYPE = np.dtype([("xyz", "<f4", (3,)), ("rgba", "u1", (4,))])


def stamp(ns: int) -> Timestamp:
    ts = Timestamp()
    ts.FromNanoseconds(int(ns))
    return ts


def color(rgba) -> Color:
    r, g, b, a = (float(v) for v in rgba)
    return Color(r=r, g=g, b=b, a=a)


def pose(T=None, position=None) -> Pose:
    """A foxglove Pose from a 4x4 transform (or a bare position, unrotated)."""
    p = Pose()
    if T is not None:
        T = np.asarray(T, dtype=np.float64)
        position = T[:3, 3]
        q = matrix_to_quaternion(T[:3, :3])
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (float(v) for v in q)
    else:
        p.orientation.w = 1.0
    if position is not None:
        p.position.x, p.position.y, p.position.z = (float(v) for v in np.asarray(position).reshape(3))
    return p


def metadata(**items) -> list[KeyValuePair]:
    return [KeyValuePair(key=k, value=str(v)) for k, v in items.items()]


def frame_transform(ns: int, parent: str, child: str, T) -> FrameTransform:
    p = pose(T)
    return FrameTransform(timestamp=stamp(ns), parent_frame_id=parent, child_frame_id=child,
                          translation={"x": p.position.x, "y": p.position.y, "z": p.position.z},
                          rotation={"x": p.orientation.x, "y": p.orientation.y, "z": p.orientation.z,
                                    "w": p.orientation.w})


def poses_in_frame(ns: int, frame: str, poses=None, positions=None) -> PosesInFrame:
    """A path: (N, 4, 4) poses, or (N, 3) positions with no orientation (identity)."""
    msg = PosesInFrame(timestamp=stamp(ns), frame_id=frame)
    if poses is not None:
        msg.poses.extend(pose(T) for T in np.asarray(poses))
    else:
        msg.poses.extend(pose(position=p) for p in np.asarray(positions))
    return msg


def camera_calibration(ns: int, frame: str, intrinsics: dict) -> CameraCalibration:
    """The depth camera (pinhole, no distortion): Foxglove draws its frustum on the camera frame."""
    fx, fy, cx, cy = (float(intrinsics[k]) for k in ("fx", "fy", "cx", "cy"))
    return CameraCalibration(timestamp=stamp(ns), frame_id=frame, width=int(intrinsics["width"]),
                             height=int(intrinsics["height"]), distortion_model="plumb_bob", D=[0.0] * 5,
                             K=[fx, 0, cx, 0, fy, cy, 0, 0, 1], R=[1, 0, 0, 0, 1, 0, 0, 0, 1],
                             P=[fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0])


def point_cloud(ns: int, frame: str, points, colors=None) -> PointCloud:
    """(N, 3) points with (N, 3|4) colours in 0..1 or 0..255 (grey when None) as packed x, y, z float32 and
    red, green, blue, alpha uint8 (Foxglove's RGBA-fields colour mode)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    data = np.zeros(len(pts), dtype=_POINT_DTYPE)
    data["xyz"] = pts
    data["rgba"] = 255
    if colors is not None and len(pts):
        c = np.asarray(colors, dtype=np.float64)
        c = c * 255 if c.max() <= 1.0 else c
        data["rgba"][:, :c.shape[1]] = np.clip(np.rint(c), 0, 255)
    else:
        data["rgba"][:, :3] = 180
    msg = PointCloud(timestamp=stamp(ns), frame_id=frame, pose=pose(np.eye(4)), point_stride=_POINT_DTYPE.itemsize,
                     data=data.tobytes())
    msg.fields.extend(PackedElementField(name=n, offset=o, type=t) for n, o, t in _POINT_FIELDS)
    return msg


def triangle_list(vertices, triangles, colors=None, rgba=(0.7, 0.7, 0.7, 1.0), T=None) -> TriangleListPrimitive:
    """An indexed triangle mesh (vertices (N, 3), triangles (M, 3)) with per-vertex colours or one colour,
    placed by T (identity when None)."""
    prim = TriangleListPrimitive(pose=pose(np.eye(4) if T is None else T), color=color(rgba))
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    prim.points.extend(Point3(x=x, y=y, z=z) for x, y, z in v.tolist())
    prim.indices.extend(np.asarray(triangles, dtype=np.uint32).reshape(-1).tolist())
    if colors is not None and len(v):
        c = np.asarray(colors, dtype=np.float64).reshape(len(v), -1)
        prim.colors.extend(Color(r=r, g=g, b=b, a=1.0) for r, g, b in c[:, :3].tolist())
    return prim


def frustum_points(intrinsics: dict, depth: float) -> np.ndarray:
    """(16, 3) camera-frame points of a LINE_LIST frustum: 4 edges from the optical centre to the image corners
    at `depth` metres, then the 4 sides of the far rectangle."""
    fx, fy, cx, cy = (float(intrinsics[k]) for k in ("fx", "fy", "cx", "cy"))
    w, h = float(intrinsics["width"]), float(intrinsics["height"])
    corners = np.array([[(u - cx) / fx * depth, (v - cy) / fy * depth, depth]
                        for u, v in ((0, 0), (w, 0), (w, h), (0, h))])
    edges = [p for c in corners for p in (np.zeros(3), c)]
    sides = [p for i in range(4) for p in (corners[i], corners[(i + 1) % 4])]
    return np.array(edges + sides)


def frustum(T, intrinsics: dict, depth: float, rgba) -> LinePrimitive:
    """A camera view as a wire frustum placed at T (camera-to-world, optical frame: z forward, y down)."""
    prim = LinePrimitive(type=LinePrimitive.LINE_LIST, pose=pose(T), thickness=2.0, scale_invariant=True,
                         color=color(rgba))
    prim.points.extend(Point3(x=x, y=y, z=z) for x, y, z in frustum_points(intrinsics, depth).tolist())
    return prim


def line_strip(points, rgba, thickness: float = 2.0) -> LinePrimitive:
    prim = LinePrimitive(type=LinePrimitive.LINE_STRIP, pose=pose(np.eye(4)), thickness=thickness,
                         scale_invariant=True, color=color(rgba))
    prim.points.extend(Point3(x=x, y=y, z=z) for x, y, z in np.asarray(points, dtype=np.float64).tolist())
    return prim


def superquadric_surface(size, exponents, n_lat: int = 16, n_lon: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (in the superquadric's own frame) and triangles of its surface, from the parametric form
    x = a1 c(eta)^e1 c(w)^e2, y = a2 c(eta)^e1 s(w)^e2, z = a3 s(eta)^e1 (signed powers), the counterpart of
    the inside-outside function of segmentation.superquadric: every vertex has F = 1."""
    a = np.asarray(size, dtype=np.float64)
    e1, e2 = float(exponents[0]), float(exponents[1])
    eta = np.linspace(-np.pi / 2, np.pi / 2, n_lat + 1)
    w = np.linspace(-np.pi, np.pi, n_lon, endpoint=False)
    E, W = np.meshgrid(eta, w, indexing="ij")

    def spow(x, m):
        return np.sign(x) * np.abs(x) ** m

    ce = spow(np.cos(E), e1)
    v = np.stack([a[0] * ce * spow(np.cos(W), e2), a[1] * ce * spow(np.sin(W), e2), a[2] * spow(np.sin(E), e1)],
                 axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_lat), np.arange(n_lon), indexing="ij")
    p00 = i * n_lon + j
    p01 = i * n_lon + (j + 1) % n_lon
    p10 = p00 + n_lon
    p11 = p01 + n_lon
    tris = np.concatenate([np.stack([p00, p01, p11], -1).reshape(-1, 3), np.stack([p00, p11, p10], -1).reshape(-1, 3)])
    return v, tris


def entity(ns: int, frame: str, entity_id: str, **parts) -> SceneEntity:
    """A scene entity that stays until replaced (lifetime 0), its primitives given by kind (lines=[...], ...)."""
    e = SceneEntity(timestamp=stamp(ns), frame_id=frame, id=entity_id)
    for kind, items in parts.items():
        getattr(e, kind).extend(items)
    return e
