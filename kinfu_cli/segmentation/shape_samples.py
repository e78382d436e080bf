"""Generated point clouds of known shapes: primitives (for the shape prior's training and held-out test) and
composites of known parts (L, T, bottle, mug: for the multi-superquadric split).

Surfaces are sampled on open3d meshes (true boxes, cylinders, spheres, cones, tori, not superquadrics, so the
fit is not tested on its own model), with Gaussian noise; a composite keeps only the points on the union's
outer surface, and a partial view keeps the points whose normal faces one of a few sensors.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from kinfu_cli.core.errors import ConfigError

PRIMITIVES = ("box", "cylinder", "sphere", "cone", "ellipsoid", "capsule")
# composite name -> number of parts
COMPOSITES = {"L": 2, "T": 2, "bottle": 2, "mug": 2}


def _mesh(kind: str, dims: dict) -> o3d.geometry.TriangleMesh:
    """A watertight mesh centred on its bounding box, in its own frame (axis along z)."""
    if kind == "box":
        m = o3d.geometry.TriangleMesh.create_box(*dims["extents"])
        m.translate(-np.asarray(dims["extents"]) / 2)
    elif kind == "cylinder":
        m = o3d.geometry.TriangleMesh.create_cylinder(dims["radius"], dims["height"], resolution=48, split=4)
    elif kind == "sphere":
        m = o3d.geometry.TriangleMesh.create_sphere(dims["radius"], resolution=30)
    elif kind == "ellipsoid":
        m = o3d.geometry.TriangleMesh.create_sphere(1.0, resolution=30)
        m.vertices = o3d.utility.Vector3dVector(np.asarray(m.vertices) * np.asarray(dims["radii"]))
    elif kind == "cone":
        m = o3d.geometry.TriangleMesh.create_cone(dims["radius"], dims["height"], resolution=48, split=4)
        m.translate([0, 0, -dims["height"] / 2])
    elif kind == "capsule":  # a cylinder with hemispherical caps: between the cylinder and the ellipsoid
        r, h = dims["radius"], dims["height"]
        m = o3d.geometry.TriangleMesh.create_sphere(r, resolution=30)
        v = np.asarray(m.vertices).copy()
        v[:, 2] += np.sign(v[:, 2]) * h / 2
        m.vertices = o3d.utility.Vector3dVector(v)
    elif kind == "torus":
        m = o3d.geometry.TriangleMesh.create_torus(dims["torus_radius"], dims["tube_radius"], 40, 16)
    else:
        raise ConfigError(f"unknown shape {kind!r}: expected one of {', '.join(PRIMITIVES + ('torus',))}",
                          parameter="kind")
    m.compute_vertex_normals()
    return m


def _sample(mesh: o3d.geometry.TriangleMesh, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    o3d.utility.random.seed(int(seed))
    pc = mesh.sample_points_uniformly(int(n), use_triangle_normal=True)
    return np.asarray(pc.points), np.asarray(pc.normals)


def random_primitive_dims(kind: str, rng: np.random.Generator) -> dict:
    """Random dimensions (3-20 cm, the thesis' objects) of a primitive."""
    if kind == "box":
        return {"extents": rng.uniform(0.03, 0.2, 3)}
    if kind in ("cylinder", "cone"):
        return {"radius": rng.uniform(0.015, 0.07), "height": rng.uniform(0.04, 0.2)}
    if kind == "capsule":
        return {"radius": rng.uniform(0.015, 0.05), "height": rng.uniform(0.03, 0.12)}
    if kind == "sphere":
        return {"radius": rng.uniform(0.02, 0.08)}
    if kind == "ellipsoid":
        return {"radii": rng.uniform(0.02, 0.09, 3)}
    raise ConfigError(f"unknown shape {kind!r}: expected one of {', '.join(PRIMITIVES)}", parameter="kind")


def primitive_cloud(kind: str, rng: np.random.Generator, *, n: int = 1500, noise: float = 0.001,
                    partial: bool = False, dims: dict | None = None) -> np.ndarray:
    """Points (about n, 3) on a randomly placed and rotated primitive of that kind, randomly sized unless `dims`
    is given; `partial` keeps the side seen by 1-3 sensors above the object (as a table-top scan sees it)."""
    mesh = _mesh(kind, dims if dims is not None else random_primitive_dims(kind, rng))
    pts, nrm = _sample(mesh, 3 * n if partial else n, int(rng.integers(1 << 30)))
    R = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
    pts, nrm = pts @ R.T, nrm @ R.T
    if partial:
        az = rng.uniform(0, 2 * np.pi) + np.radians(60) * np.arange(int(rng.integers(1, 4)))
        el = np.radians(rng.uniform(20, 60))
        dirs = np.stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.full(len(az), np.sin(el))], 1)
        seen = ((nrm @ dirs.T) > 0.05).any(axis=1)
        pts = pts[seen][:n]
    pts = pts + rng.uniform(-0.5, 0.5, 3)
    return pts + rng.normal(scale=noise, size=pts.shape)


def _composite_parts(name: str) -> list[tuple[str, dict, np.ndarray, np.ndarray]]:
    """(kind, dims, rotation, centre) of each part, in the object frame (z up)."""
    eye = np.eye(3)
    if name == "L":  # a horizontal bar with an upright at one end
        return [("box", {"extents": [0.20, 0.05, 0.05]}, eye, np.array([0.0, 0, 0.025])),
                ("box", {"extents": [0.05, 0.05, 0.12]}, eye, np.array([0.075, 0, 0.11]))]
    if name == "T":  # an upright stem under a cross bar
        return [("box", {"extents": [0.04, 0.04, 0.15]}, eye, np.array([0.0, 0, 0.075])),
                ("box", {"extents": [0.20, 0.04, 0.04]}, eye, np.array([0.0, 0, 0.17]))]
    if name == "bottle":  # a body and a thinner neck
        return [("cylinder", {"radius": 0.035, "height": 0.15}, eye, np.array([0.0, 0, 0.075])),
                ("cylinder", {"radius": 0.012, "height": 0.06}, eye, np.array([0.0, 0, 0.18]))]
    if name == "mug":  # a body and a handle ring standing in the x-z plane, its inner half inside the body
        ring = Rotation.from_euler("x", 90, degrees=True).as_matrix()
        return [("cylinder", {"radius": 0.04, "height": 0.10}, eye, np.array([0.0, 0, 0.05])),
                ("torus", {"torus_radius": 0.03, "tube_radius": 0.008}, ring, np.array([0.045, 0, 0.05]))]
    raise ConfigError(f"unknown composite {name!r}: expected one of {', '.join(COMPOSITES)}", parameter="name")


def composite_cloud(name: str, rng: np.random.Generator, *, spacing: float = 0.004, noise: float = 0.001
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Points on the outer surface of a composite of known parts, randomly rotated, and each point's part
    index. Points of one part inside another part are dropped."""
    meshes = []
    for kind, dims, R, c in _composite_parts(name):
        m = _mesh(kind, dims)
        m.rotate(R, center=np.zeros(3))
        m.translate(c)
        meshes.append(m)
    pts_all, lab_all = [], []
    for k, m in enumerate(meshes):
        n = max(50, int(m.get_surface_area() / spacing ** 2))
        pts, _ = _sample(m, n, int(rng.integers(1 << 30)))
        pts_all.append(pts)
        lab_all.append(np.full(len(pts), k))
    pts, lab = np.concatenate(pts_all), np.concatenate(lab_all)
    # inside another part: the occupancy of the union counts more than the point's own (odd) crossing
    occ = np.zeros(len(pts), dtype=bool)
    for k, m in enumerate(meshes):
        one = o3d.t.geometry.RaycastingScene()
        one.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(m))
        d = one.compute_signed_distance(o3d.core.Tensor(pts.astype(np.float32))).numpy()
        occ |= (lab != k) & (d < -1e-3)
    pts, lab = pts[~occ], lab[~occ]
    R = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
    pts = pts @ R.T + rng.uniform(-0.5, 0.5, 3)
    return pts + rng.normal(scale=noise, size=pts.shape), lab
