"""A known object as a watertight triangle mesh in its own (model) frame, with open3d's RaycastingScene for
closest points and unsigned distances (the proximity likelihood of thesis eqs. 4.13-4.17).

Poses are 6-vectors x = [tx, ty, tz, phi, theta, psi] (metres, radians): the model-to-world transform
p_world = R(x) p_model + t with R = Rz(phi) Ry(theta) Rx(psi) (scipy intrinsic "ZYX"); the thesis does not
state its Euler convention, this one puts theta (prior std pi/2 in Table 4.1) in the middle.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.core.errors import KinfuError
from kinfu_cli.io.mesh_faces import faces_outside_vertices
from kinfu_cli.io.messages import c_stderr_silenced
from kinfu_cli.localization.distance_field import sample_field

EULER = "ZYX"


class LocalizationError(KinfuError):
    """A model or points file that cannot be used for localisation (one line naming the file)."""


def euler_matrices(angles: np.ndarray) -> np.ndarray:
    """(..., 3) intrinsic ZYX angles -> (..., 3, 3) Rz(phi) Ry(theta) Rx(psi), written out in numpy: the filters
    convert ~10^4 poses per step, where scipy's Rotation.from_euler is ~10x slower (benchmarks/
    bench_localize.py measures the ratio; tests check equality with scipy)."""
    a = np.asarray(angles, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    cz, cy, cx = c[..., 0], c[..., 1], c[..., 2]
    sz, sy, sx = s[..., 0], s[..., 1], s[..., 2]
    R = np.empty(a.shape[:-1] + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx
    R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx
    R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = -sy, cy * sx, cy * cx
    return R


def pose_rotations(poses: np.ndarray) -> np.ndarray:
    """(..., 6) pose vectors -> (..., 3, 3) rotation matrices (model to world)."""
    return euler_matrices(np.asarray(poses, dtype=np.float64)[..., 3:6])


def pose_matrix(pose: np.ndarray) -> np.ndarray:
    """A 4x4 model-to-world transform from one pose vector."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler(EULER, np.asarray(pose)[3:6]).as_matrix()
    T[:3, 3] = np.asarray(pose)[:3]
    return T


def matrix_pose(T: np.ndarray) -> np.ndarray:
    """The pose vector of a 4x4 rigid transform."""
    return np.concatenate([np.asarray(T)[:3, 3], Rotation.from_matrix(np.asarray(T)[:3, :3]).as_euler(EULER)])


@dataclass
class MeshModel:
    """vertices (V, 3) and triangles (F, 3) of a closed surface; `name` for reports."""

    vertices: np.ndarray
    triangles: np.ndarray
    name: str = "model"

    def __post_init__(self) -> None:
        import open3d as o3d  # heavy; only the closest-point queries need it

        self.vertices = np.asarray(self.vertices, dtype=np.float64)
        self.triangles = np.asarray(self.triangles, dtype=np.int64)
        self.field = None  # a DistanceField once build_field ran
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(o3d.core.Tensor(self.vertices.astype(np.float32)),
                                  o3d.core.Tensor(self.triangles.astype(np.uint32)))
        a, b, c = (self.vertices[self.triangles[:, k]] for k in range(3))
        self.areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)

    @property
    def diameter(self) -> float:
        """Diagonal of the axis-aligned bounding box (m)."""
        return float(np.linalg.norm(self.vertices.max(0) - self.vertices.min(0)))

    def exact_closest_points(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) model-frame points -> the closest surface points (..., 3), from the BVH."""
        import open3d as o3d

        pts = np.asarray(points, dtype=np.float32)
        res = self._scene.compute_closest_points(o3d.core.Tensor(pts.reshape(-1, 3)))
        return res["points"].numpy().astype(np.float64).reshape(pts.shape)

    def exact_distances(self, points: np.ndarray, signed: bool = False) -> np.ndarray:
        """(..., 3) model-frame points -> (signed: negative inside) distance to the surface (...), from the BVH."""
        import open3d as o3d

        pts = np.asarray(points, dtype=np.float32)
        fn = self._scene.compute_signed_distance if signed else self._scene.compute_distance
        return fn(o3d.core.Tensor(pts.reshape(-1, 3))).numpy().astype(np.float64).reshape(pts.shape[:-1])

    def build_field(self, cells: int = 64, margin: float = 0.3) -> None:
        """Sample the signed distance and closest-point normals on a grid (`cells` per side over the bounding
        box grown by `margin` diameters) once (`distance_field`); `closest_points` / `distances` and the filters'
        kernels then look it up. Idempotent for the same arguments."""
        if getattr(self, "_field_args", None) == (cells, margin):
            return
        self.field = sample_field(self.vertices, lambda g: self.exact_distances(g, signed=True),
                                  self.exact_closest_points, cells, margin)
        self._field_args = (cells, margin)

    def closest_points(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) model-frame points -> closest surface points: from the field when built, else the BVH."""
        field = getattr(self, "field", None)
        return self.exact_closest_points(points) if field is None else field.closest_points(points)

    def distances(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) model-frame points -> unsigned distance to the surface: from the field when built, else the
        BVH."""
        field = getattr(self, "field", None)
        return self.exact_distances(points) if field is None else field.distances(points)

    def world_distances(self, poses: np.ndarray, points: np.ndarray) -> np.ndarray:
        """Distance of world points (M, 3) to the model at each pose (P, 6) -> (P, M): the points go into the
        model frame (R^T (y - t)), where the scene lives (a numba kernel over the field when built)."""
        poses = np.asarray(poses, dtype=np.float64)
        R = pose_rotations(poses)
        if self.field is not None:
            from kinfu_cli.localization.ukf import pose_distances

            f = self.field
            out = np.empty((len(poses), len(points)))
            pose_distances(np.ascontiguousarray(poses[:, :3]), np.ascontiguousarray(R),
                           np.ascontiguousarray(points, dtype=np.float64), f.lo, f.step, f.sdf, f.normals, out)
            return out
        local = np.einsum("pji,pmj->pmi", R, np.asarray(points)[None] - poses[:, None, :3])
        return self.distances(local)

    def performance_index(self, pose: np.ndarray, points: np.ndarray) -> float:
        """I_L of eq. 4.30: mean (unsquared) distance of the measurements to the model at `pose` (m)."""
        R = pose_rotations(np.asarray(pose)[None])[0]
        return float(self.exact_distances((np.asarray(points) - np.asarray(pose)[:3]) @ R).mean())

    def sample_surface(self, n: int, rng: np.random.Generator, with_normals: bool = False):
        """n points uniform by area on the surface (model frame); with_normals: also their unit face normals,
        as (points, normals)."""
        tri = rng.choice(len(self.triangles), size=n, p=self.areas / self.areas.sum())
        u, v = rng.random(n), rng.random(n)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        a, b, c = (self.vertices[self.triangles[tri, k]] for k in range(3))
        points = a + u[:, None] * (b - a) + v[:, None] * (c - a)
        if not with_normals:
            return points
        nrm = np.cross(b - a, c - a)
        return points, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def check_mesh(vertices: np.ndarray, triangles: np.ndarray, source: str) -> None:
    """Refuse an empty or non-watertight mesh: inside / outside and closest points need a closed surface."""
    if len(vertices) == 0 or len(triangles) == 0:
        raise LocalizationError(f"{source}: empty mesh (expected a closed triangle mesh)")
    if not np.all(np.isfinite(vertices)):
        raise LocalizationError(f"{source}: mesh vertices are not finite")
    if (outside := faces_outside_vertices(len(vertices), triangles)) is not None:
        raise LocalizationError(f"{source}: {outside}")
    tri = np.sort(np.asarray(triangles), axis=1)
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]])
    _, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = int(np.sum(counts != 2))
    if open_edges:
        raise LocalizationError(f"{source}: mesh is not watertight ({open_edges} edges not shared by exactly two "
                                f"triangles; expected a closed surface)")


def read_mesh(path: str | os.PathLike) -> MeshModel:
    """A watertight triangle mesh from a PLY/OBJ/STL file (LocalizationError when unusable)."""
    import open3d as o3d

    path = Path(path)
    if not path.is_file():
        raise LocalizationError(f"{path}: no such mesh file")
    with open(path, "rb") as fh:
        head = fh.read(3)
    if path.suffix.lower() == ".ply" and head != b"ply":
        raise LocalizationError(f"{path}: not a PLY file")
    level = o3d.utility.get_verbosity_level()
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)  # no reader chatter on stderr
    try:
        with c_stderr_silenced():  # RPly writes its own lines on a damaged PLY
            mesh = o3d.io.read_triangle_mesh(str(path), print_progress=False)
    finally:
        o3d.utility.set_verbosity_level(level)
    mesh.remove_duplicated_vertices()
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    check_mesh(v, f, str(path))
    return MeshModel(v, f, name=path.stem)
