"""Generated test meshes: the five kinds of the thesis' simulation (Fig. 4.1: box 0.1 x 0.3 x 0.2 m,
tetrahedron with a 0.33 m equilateral base and 0.2 m height, a cleaner-spray-like bottle about
0.23 x 0.08 x 0.05 m, a toy-robot-like composite about 0.23 x 0.09 x 0.06 m, a helmet-like dome of radius
0.1 m) and six near-identical pairs for recognition as in ch. 5 (arched vs saw-tooth top, smooth ramp vs
staircase, straight vs curved bottom edge).

Box and tetrahedron are exact polyhedra; the others are unions / differences of signed distance functions
meshed by marching cubes (scikit-image) and decimated (open3d), so each is one closed surface. Every mesh is
centred on its bounding-box centre (the model frame's origin).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from kinfu_cli.localization.mesh_model import MeshModel, check_mesh

SYMMETRIC = {"box", "tetrahedron", "helmet"}  # poses equivalent under a rotation exist (scored by ADD-S)


def _box(p, centre, half):
    q = np.abs(p - np.asarray(centre)) - np.asarray(half)
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)


def _cyl_z(p, centre, r, half_h):
    d = p - np.asarray(centre)
    q = np.stack([np.linalg.norm(d[..., :2], axis=-1) - r, np.abs(d[..., 2]) - half_h], -1)
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)


def _cyl_y(p, centre, r, half_len):
    d = p - np.asarray(centre)
    q = np.stack([np.linalg.norm(d[..., [0, 2]], axis=-1) - r, np.abs(d[..., 1]) - half_len], -1)
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)


def _sphere(p, centre, r):
    return np.linalg.norm(p - np.asarray(centre), axis=-1) - r


def _polygon(name: str, vertices, triangles) -> MeshModel:
    v = np.asarray(vertices, dtype=float)
    v -= 0.5 * (v.min(0) + v.max(0))
    return MeshModel(v, np.asarray(triangles), name=name)


def _from_sdf(name: str, sdf: Callable[[np.ndarray], np.ndarray], lo, hi, step: float = 0.003,
              faces: int = 3000) -> MeshModel:
    import open3d as o3d
    from skimage.measure import marching_cubes

    lo, hi = np.asarray(lo, float) - 2 * step, np.asarray(hi, float) + 2 * step
    axes = [np.arange(a, b + step, step) for a, b in zip(lo, hi)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    vol = sdf(grid)
    verts, tris, _, _ = marching_cubes(vol, level=0.0, spacing=(step, step, step), allow_degenerate=False)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(verts + lo), o3d.utility.Vector3iVector(tris))
    mesh.remove_duplicated_vertices()
    mesh.remove_degenerate_triangles()
    simple = mesh.simplify_quadric_decimation(faces)
    simple.remove_unreferenced_vertices()
    v, f = np.asarray(simple.vertices), np.asarray(simple.triangles)
    try:
        check_mesh(v, f, name)
    except Exception:  # decimation opened the surface: keep the full marching-cubes mesh
        v, f = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    v = v - 0.5 * (v.min(0) + v.max(0))
    return MeshModel(v, f, name=name)


def box() -> MeshModel:
    hx, hy, hz = 0.05, 0.15, 0.1
    v = [[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    f = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
         [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return _polygon("box", v, f)


def tetrahedron() -> MeshModel:
    s, h = 0.33, 0.2
    r = s / np.sqrt(3)
    base = [[r * np.cos(a), r * np.sin(a), 0.0] for a in (0, 2 * np.pi / 3, 4 * np.pi / 3)]
    return _polygon("tetrahedron", base + [[0, 0, h]], [[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]])


@functools.cache
def cleaner() -> MeshModel:
    """A spray bottle: flattened body, neck, a trigger head leaning forward and a nozzle (no symmetry)."""
    def sdf(p):
        body = _box(p, (0, 0, 0.075), (0.035, 0.02, 0.075)) - 0.004
        shoulder = _cyl_z(p, (0, 0, 0.16), 0.016, 0.012)
        head = _box(p, (0.015, 0, 0.195), (0.035, 0.014, 0.022)) - 0.003
        nozzle = _cyl_z(p[..., [2, 1, 0]], (0.205, 0, 0.06), 0.006, 0.012)
        trigger = _box(p, (0.03, 0, 0.155), (0.006, 0.008, 0.02))
        return np.minimum.reduce([body, shoulder, head, nozzle, trigger])
    return _from_sdf("cleaner", sdf, (-0.04, -0.025, -0.005), (0.075, 0.025, 0.22))


@functools.cache
def robot() -> MeshModel:
    """A toy robot of boxes: legs, torso, one raised arm, a backpack, head with a nose and an off-centre
    antenna (no symmetry)."""
    def sdf(p):
        parts = [_box(p, (-0.015, 0, 0.04), (0.01, 0.015, 0.04)), _box(p, (0.015, 0, 0.04), (0.01, 0.015, 0.04)),
                 _box(p, (0, 0, 0.115), (0.03, 0.02, 0.04)), _box(p, (-0.04, 0, 0.13), (0.01, 0.012, 0.03)),
                 _box(p, (0.04, 0.02, 0.15), (0.01, 0.03, 0.01)), _box(p, (0, 0, 0.18), (0.02, 0.018, 0.025)),
                 _cyl_z(p, (0.01, 0, 0.215), 0.004, 0.012), _box(p, (0, -0.03, 0.125), (0.022, 0.012, 0.028)),
                 _box(p, (0.008, 0.022, 0.185), (0.006, 0.006, 0.005))]
        return np.minimum.reduce(parts)
    return _from_sdf("robot", sdf, (-0.05, -0.045, 0), (0.05, 0.05, 0.23))


@functools.cache
def helmet() -> MeshModel:
    """A solid half-sphere of radius 0.1 m (rotationally symmetric about its axis)."""
    return _from_sdf("helmet", lambda p: np.maximum(_sphere(p, (0, 0, 0), 0.1), -p[..., 2]),
                     (-0.1, -0.1, 0), (0.1, 0.1, 0.1), step=0.004)


SIMULATION_SHAPES: dict[str, Callable[[], MeshModel]] = {
    "box": box, "tetrahedron": tetrahedron, "cleaner": cleaner, "robot": robot, "helmet": helmet}
# Table 4.3: measurements L and window m per object
TABLE_4_3 = {"box": (15, 9), "tetrahedron": (30, 12), "cleaner": (62, 36), "helmet": (60, 36), "robot": (40, 24)}


def _block(p):
    return _box(p, (0, 0, 0.02), (0.04, 0.025, 0.02))


RECOGNITION_NAMES = ("a_arched", "b_sawtooth", "c_ramp", "d_steps", "e_straight", "f_curved")


def recognition_shapes() -> tuple[MeshModel, ...]:
    """The six recognition blocks in the order of RECOGNITION_NAMES."""
    return tuple(recognition_shape(n) for n in RECOGNITION_NAMES)


@functools.cache
def recognition_shape(name: str) -> MeshModel:
    """Six wooden-toy-like blocks in three near-identical pairs (ch. 5, Fig. 5.2): (a) arched top, (b) saw-tooth
    top, (c) smooth quarter-round ramp, (d) the same ramp as four steps, (e) straight bottom edge with a
    rectangular notch, (f) the notch with a curved (arched) edge."""
    lo, hi = (-0.04, -0.025, 0), (0.04, 0.025, 0.06)

    def arched(p):
        return np.minimum(_block(p), np.maximum(_cyl_y(p, (0, 0, 0.02), 0.04, 0.025), -p[..., 2] + 0.02))

    def sawtooth(p):
        tooth = 0.04 - 0.04 * np.abs(((p[..., 0] + 0.04) / 0.02) % 2 - 1) * 0.5 - 0.01
        top = np.maximum(np.maximum(p[..., 2] - 0.02 - tooth, -p[..., 2]),
                         np.maximum(np.abs(p[..., 0]) - 0.04, np.abs(p[..., 1]) - 0.025))
        return np.minimum(_block(p), top)

    def ramp(p):
        base = _box(p, (0, 0, 0.03), (0.04, 0.025, 0.03))
        return np.maximum(base, -_cyl_y(p, (0.04, 0, 0.06), 0.05, 0.03))

    def steps(p):
        parts = [_box(p, (-0.04 + 0.01 * (k + 1) - 0.0, 0, 0.03 - 0.0075 * k / 1.0), (0.01 * (k + 1), 0.025,
                                                                                    0.03 - 0.0075 * k))
                 for k in range(4)]
        return np.maximum(np.minimum.reduce(parts), _box(p, (0, 0, 0.03), (0.04, 0.025, 0.03)))

    def notch_straight(p):
        return np.maximum(_box(p, (0, 0, 0.025), (0.04, 0.025, 0.025)), -_box(p, (0, 0, 0), (0.02, 0.03, 0.015)))

    def notch_curved(p):
        return np.maximum(_box(p, (0, 0, 0.025), (0.04, 0.025, 0.025)), -_cyl_y(p, (0, 0, 0), 0.02, 0.03))

    specs = [("a_arched", arched, hi), ("b_sawtooth", sawtooth, hi), ("c_ramp", ramp, hi),
             ("d_steps", steps, hi), ("e_straight", notch_straight, (0.04, 0.025, 0.05)),
             ("f_curved", notch_curved, (0.04, 0.025, 0.05))]
    spec = {n: (f, top) for n, f, top in specs}
    if name not in spec:
        raise KeyError(name)
    f, top = spec[name]
    return _from_sdf(name, f, lo, top, step=0.002, faces=2000)
