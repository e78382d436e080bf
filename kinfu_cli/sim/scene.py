"""Synthetic tabletop scenes: a table on a floor with boxes, cylinders, spheres and meshes (torus, cone).

World frame: z up, metres. The table is centred at (0, 0) in x-y, its top at z = `top_z` (0.7 m by default) and
1.2 x 0.8 m large; the person stands on the -y side, the robot on the +y side. Objects rest on the table top.

A `Scene` is immutable in use: `scene.with_change(...)` returns a new scene with one object placed, removed or moved,
so a recording scenario keeps both states. `scene.mesh()` is the whole scene as one open3d TriangleMesh (what the
sensor sees), `scene.raycasting_scene()` the same ready for open3d's RaycastingScene with a label and a colour per
geometry id (the simulated sensor uses those for colour and label images).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d

from kinfu_cli.core.errors import ConfigError

SHAPES = ("box", "cylinder", "sphere", "torus", "cone")

# Distinct, saturated object colours (RGB 0..1); the table is wood-like, the floor grey.
PALETTE = np.array([
    [0.85, 0.15, 0.15], [0.15, 0.55, 0.85], [0.20, 0.70, 0.25], [0.95, 0.75, 0.10],
    [0.60, 0.25, 0.75], [0.95, 0.45, 0.10], [0.10, 0.75, 0.70], [0.85, 0.35, 0.60],
])
TABLE_COLOUR = np.array([0.62, 0.45, 0.28])
FLOOR_COLOUR = np.array([0.45, 0.45, 0.47])

# Labels used in label images: 0 = nothing hit, 1 = floor, 2 = table, 3.. = objects in scene order.
LABEL_NONE, LABEL_FLOOR, LABEL_TABLE = 0, 1, 2


@dataclass(frozen=True)
class Table:
    """A table: top centred at (center[0], center[1], top_z), size (x, y) metres, with four legs."""

    center: tuple[float, float] = (0.0, 0.0)
    size: tuple[float, float] = (1.2, 0.8)
    top_z: float = 0.7
    thickness: float = 0.04
    leg_width: float = 0.05

    def contains_xy(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """True where the (..., 2) points lie on the table top, at least `margin` from its edges."""
        xy = np.asarray(xy, dtype=float)
        half = np.asarray(self.size) / 2 - margin
        return np.all(np.abs(xy - np.asarray(self.center)) <= half, axis=-1)

    def mesh(self) -> o3d.geometry.TriangleMesh:
        sx, sy = self.size
        cx, cy = self.center
        top = _box_mesh((sx, sy, self.thickness), (cx, cy, self.top_z - self.thickness / 2))
        legs_h = self.top_z - self.thickness
        inset = 0.06
        for dx in (-1, 1):
            for dy in (-1, 1):
                c = (cx + dx * (sx / 2 - inset), cy + dy * (sy / 2 - inset), legs_h / 2)
                top += _box_mesh((self.leg_width, self.leg_width, legs_h), c)
        top.compute_vertex_normals()
        return top

    def to_json(self) -> dict:
        return {"center": [float(self.center[0]), float(self.center[1])], "size": [float(s) for s in self.size],
                "top_z": float(self.top_z), "thickness": float(self.thickness),
                "plane": [0.0, 0.0, 1.0, -float(self.top_z)]}


@dataclass(frozen=True)
class SceneObject:
    """One object resting on the table.

    id: name used in files (`objects/<id>.ply`). shape: one of SHAPES. center: (3,) centre of its bounding box in
    world. size: (3,) axis-aligned extents in the object frame (before `yaw`). params: shape parameters (radius,
    height, ...). colour: RGB 0..1. yaw: rotation about world z (radians). present: whether it is in the scene.
    """

    id: str
    shape: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    params: dict
    colour: tuple[float, float, float]
    yaw: float = 0.0
    present: bool = True

    @property
    def footprint_radius(self) -> float:
        """Radius of the circle around the object's x-y centre that covers its footprint."""
        return float(np.hypot(self.size[0], self.size[1]) / 2)

    @property
    def mesh(self) -> o3d.geometry.TriangleMesh:
        """The object's mesh in world coordinates (built on demand)."""
        return _object_mesh(self)

    def moved_to(self, xy: tuple[float, float], yaw: float | None = None) -> "SceneObject":
        return dataclasses.replace(self, center=(float(xy[0]), float(xy[1]), float(self.center[2])),
                                   yaw=self.yaw if yaw is None else float(yaw))

    def to_json(self) -> dict:
        return {"id": self.id, "shape": self.shape, "center": [float(c) for c in self.center],
                "size": [float(s) for s in self.size], "params": {k: float(v) for k, v in self.params.items()},
                "colour": [float(c) for c in self.colour], "yaw": float(self.yaw)}


@dataclass
class RaycastTarget:
    """An open3d RaycastingScene plus, per geometry id, a label and an RGB albedo (0..1)."""

    scene: o3d.t.geometry.RaycastingScene
    labels: np.ndarray  # (G,) int32
    albedo: np.ndarray  # (G, 3) float
    textured: np.ndarray  # (G,) int: 0 plain, 1 table wood stripes, 2 floor checker
    vertex_colours: list = field(default_factory=list)  # per geometry: None or (vertex colours, triangles)


@dataclass(frozen=True)
class Scene:
    """A table, an optional floor and objects; only objects with `present=True` are part of the geometry."""

    table: Table
    objects: tuple[SceneObject, ...]
    floor: bool = True
    seed: int = 0

    # ---- queries -------------------------------------------------------------------------------
    @property
    def present_objects(self) -> list[SceneObject]:
        return [o for o in self.objects if o.present]

    def object(self, object_id: str) -> SceneObject:
        for o in self.objects:
            if o.id == object_id:
                return o
        raise ConfigError(f"scene has no object {object_id!r} (objects: {', '.join(o.id for o in self.objects)})")

    def label_of(self, object_id: str) -> int:
        """Label of an object in label images (3 + its index in `objects`)."""
        return 3 + [o.id for o in self.objects].index(object_id)

    def floor_mesh(self) -> o3d.geometry.TriangleMesh:
        m = _box_mesh((4.0, 4.0, 0.02), (self.table.center[0], self.table.center[1], -0.01))
        m.compute_vertex_normals()
        return m

    def mesh(self, include_table: bool = True, include_floor: bool | None = None,
             colours: bool = True) -> o3d.geometry.TriangleMesh:
        """All present geometry as one TriangleMesh in world coordinates (vertex colours when `colours`)."""
        include_floor = self.floor if include_floor is None else include_floor
        parts: list[tuple[o3d.geometry.TriangleMesh, np.ndarray]] = []
        if include_floor:
            parts.append((self.floor_mesh(), FLOOR_COLOUR))
        if include_table:
            parts.append((self.table.mesh(), TABLE_COLOUR))
        parts += [(o.mesh, np.asarray(o.colour)) for o in self.present_objects]
        out = o3d.geometry.TriangleMesh()
        for m, c in parts:
            if colours:
                m.paint_uniform_color(c)
            out += m
        out.compute_vertex_normals()
        return out

    def raycasting_scene(self) -> RaycastTarget:
        """The present geometry in an open3d RaycastingScene, with labels and albedo per geometry id."""
        rc = o3d.t.geometry.RaycastingScene()
        labels, albedo, textured = [], [], []

        def add(mesh: o3d.geometry.TriangleMesh, label: int, colour, tex: int) -> None:
            gid = rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
            assert gid == len(labels)
            labels.append(label)
            albedo.append(np.asarray(colour, dtype=float))
            textured.append(tex)

        if self.floor:
            add(self.floor_mesh(), LABEL_FLOOR, FLOOR_COLOUR, 2)
        add(self.table.mesh(), LABEL_TABLE, TABLE_COLOUR, 1)
        for i, o in enumerate(self.objects):
            if o.present:
                add(o.mesh, 3 + i, o.colour, 0)
        return RaycastTarget(rc, np.asarray(labels, np.int32), np.asarray(albedo), np.asarray(textured, np.int32))

    # ---- changes --------------------------------------------------------------------------------
    def with_change(self, kind: str, obj: str | SceneObject, position: tuple[float, float] | None = None,
                    yaw: float | None = None) -> "Scene":
        """A new scene after one change.

        kind: "placement" (obj is a new SceneObject, or the id of an absent one; `position` x-y overrides its place),
        "removal" (obj present -> absent), "move" (pick-and-place: obj present, moved to `position` x-y).
        """
        objects = list(self.objects)
        if kind == "placement":
            if isinstance(obj, SceneObject):
                if any(o.id == obj.id for o in objects):
                    raise ConfigError(f"placement: object id {obj.id!r} already in the scene")
                new = dataclasses.replace(obj, present=True)
                if position is not None:
                    new = new.moved_to(position, yaw)
                objects.append(new)
            else:
                idx = self._index(obj)
                if objects[idx].present:
                    raise ConfigError(f"placement: object {obj!r} is already on the table")
                new = dataclasses.replace(objects[idx], present=True)
                if position is not None:
                    new = new.moved_to(position, yaw)
                objects[idx] = new
        elif kind == "removal":
            idx = self._index(obj.id if isinstance(obj, SceneObject) else obj)
            if not objects[idx].present:
                raise ConfigError(f"removal: object {objects[idx].id!r} is not on the table")
            objects[idx] = dataclasses.replace(objects[idx], present=False)
        elif kind == "move":
            idx = self._index(obj.id if isinstance(obj, SceneObject) else obj)
            if position is None:
                raise ConfigError("move: a target position is needed")
            objects[idx] = objects[idx].moved_to(position, yaw)
        else:
            raise ConfigError(f"unknown scene change {kind!r}: expected placement, removal or move")
        return dataclasses.replace(self, objects=tuple(objects))

    def free_spot(self, rng: np.random.Generator, footprint_radius: float, margin: float = 0.12,
                  clearance: float = 0.05, avoid: tuple[float, float] | None = None, min_dist: float = 0.0,
                  region: tuple[tuple[float, float], tuple[float, float]] | None = None,
                  tries: int = 2000) -> tuple[float, float]:
        """A random x-y on the table where a footprint of that radius touches no present object.

        avoid/min_dist: keep at least min_dist from that x-y (e.g. the pick location of a pick-and-place).
        region: ((xmin, xmax), (ymin, ymax)) restricts the sampling (default: the table minus `margin`).
        """
        half = np.asarray(self.table.size) / 2 - margin - footprint_radius
        c = np.asarray(self.table.center)
        lo, hi = c - half, c + half
        if region is not None:
            lo = np.maximum(lo, [region[0][0], region[1][0]])
            hi = np.minimum(hi, [region[0][1], region[1][1]])
        if np.any(hi < lo):
            raise ConfigError(f"object of radius {footprint_radius:.2f} m does not fit on the table")
        others = [(np.asarray(o.center[:2]), o.footprint_radius) for o in self.present_objects]
        for _ in range(tries):
            xy = rng.uniform(lo, hi)
            if all(np.linalg.norm(xy - p) >= r + footprint_radius + clearance for p, r in others) and \
                    (avoid is None or np.linalg.norm(xy - np.asarray(avoid)) >= min_dist):
                return float(xy[0]), float(xy[1])
        raise ConfigError(f"no free spot on the table for an object of radius {footprint_radius:.2f} m "
                          f"(too many objects: {len(others)})")

    def _index(self, object_id: str) -> int:
        for i, o in enumerate(self.objects):
            if o.id == object_id:
                return i
        raise ConfigError(f"scene has no object {object_id!r} (objects: {', '.join(o.id for o in self.objects)})")

    def to_json(self) -> dict:
        return {"table": self.table.to_json(), "objects": [o.to_json() | {"present": o.present} for o in self.objects],
                "floor": self.floor, "seed": self.seed}


# ---- construction -------------------------------------------------------------------------------------

def random_object(rng: np.random.Generator, object_id: str, shape: str, colour, table: Table) -> SceneObject:
    """An object of that shape with random dimensions (5-16 cm), resting on the table at its centre."""
    top = table.top_z
    yaw = float(rng.uniform(-np.pi, np.pi))
    if shape == "box":
        ext = rng.uniform([0.06, 0.06, 0.06], [0.16, 0.12, 0.16])
        params = {"x": ext[0], "y": ext[1], "z": ext[2]}
        size = tuple(float(e) for e in ext)
        cz = top + ext[2] / 2
    elif shape == "cylinder":
        r, h = rng.uniform(0.03, 0.055), rng.uniform(0.08, 0.18)
        params = {"radius": r, "height": h}
        size = (2 * r, 2 * r, h)
        cz = top + h / 2
    elif shape == "sphere":
        r = rng.uniform(0.035, 0.06)
        params = {"radius": r}
        size = (2 * r, 2 * r, 2 * r)
        cz = top + r
    elif shape == "torus":
        R, r = rng.uniform(0.045, 0.065), rng.uniform(0.015, 0.025)
        params = {"torus_radius": R, "tube_radius": r}
        size = (2 * (R + r), 2 * (R + r), 2 * r)
        cz = top + r
    elif shape == "cone":
        r, h = rng.uniform(0.04, 0.06), rng.uniform(0.08, 0.15)
        params = {"radius": r, "height": h}
        size = (2 * r, 2 * r, h)
        cz = top + h / 2
    else:
        raise ConfigError(f"unknown shape {shape!r}: expected one of {', '.join(SHAPES)}")
    params = {k: float(v) for k, v in params.items()}
    return SceneObject(object_id, shape, (float(table.center[0]), float(table.center[1]), float(cz)),
                       tuple(float(s) for s in size), params, tuple(float(c) for c in colour), yaw)


def make_tabletop_scene(seed: int = 0, n_objects: int = 4, table: Table | None = None,
                        floor: bool = True) -> Scene:
    """A seeded random tabletop: n_objects of mixed shapes (at least one of box, cylinder, sphere and a mesh).

    Objects are placed without overlap in the central part of the table; ids are "obj1", "obj2", ...
    """
    if n_objects < 0 or n_objects > 12:
        raise ConfigError(f"--n-objects {n_objects}: expected 0..12")
    table = table or Table()
    rng = np.random.default_rng(seed)
    base = ["box", "cylinder", "sphere", rng.choice(["torus", "cone"])]
    shapes = [base[i % 4] if i < 4 else str(rng.choice(SHAPES)) for i in range(n_objects)]
    colours = PALETTE[rng.permutation(len(PALETTE))]
    scene = Scene(table, (), floor, seed)
    for i, shape in enumerate(shapes):
        obj = random_object(rng, f"obj{i + 1}", str(shape), colours[i % len(colours)], table)
        xy = scene.free_spot(rng, obj.footprint_radius, margin=0.15)
        scene = scene.with_change("placement", obj, xy)
    return scene


# ---- meshes ------------------------------------------------------------------------------------------

def _box_mesh(extents, center) -> o3d.geometry.TriangleMesh:
    m = o3d.geometry.TriangleMesh.create_box(*[float(e) for e in extents])
    m.translate(np.asarray(center, dtype=float) - np.asarray(extents, dtype=float) / 2)
    return m


def _object_mesh(o: SceneObject) -> o3d.geometry.TriangleMesh:
    p = o.params
    if o.shape == "box":
        m = o3d.geometry.TriangleMesh.create_box(p["x"], p["y"], p["z"])
        m.translate(-np.array([p["x"], p["y"], p["z"]]) / 2)
    elif o.shape == "cylinder":
        m = o3d.geometry.TriangleMesh.create_cylinder(p["radius"], p["height"], resolution=40)
    elif o.shape == "sphere":
        m = o3d.geometry.TriangleMesh.create_sphere(p["radius"], resolution=24)
    elif o.shape == "torus":
        m = o3d.geometry.TriangleMesh.create_torus(p["torus_radius"], p["tube_radius"], radial_resolution=40,
                                                   tubular_resolution=16)
    elif o.shape == "cone":
        m = o3d.geometry.TriangleMesh.create_cone(p["radius"], p["height"], resolution=40)
        m.translate((0.0, 0.0, -p["height"] / 2))  # open3d's cone has its base at z = 0
    else:
        raise ConfigError(f"unknown shape {o.shape!r}")
    c, s = np.cos(o.yaw), np.sin(o.yaw)
    m.rotate(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), center=(0, 0, 0))
    m.translate(np.asarray(o.center, dtype=float))
    m.compute_vertex_normals()
    return m
