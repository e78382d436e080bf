"""Synthetic tabletop scenes: a table on a floor with boxes, cylinders, spheres and meshes (torus, cone).

World frame: z up, metres. The table is centred at (0, 0) in x-y, its top at z = `top_z` (0.7 m by default) and
1.2 x 0.8 m large; the person stands on the -y side, the robot on the +y side. Objects rest on the table top.

A `Scene` is immutable in use: `scene.with_change(...)` returns a new scene with one object placed, removed or moved,
so a recording scenario keeps both states. `scene.mesh()` is the whole scene as one open3d TriangleMesh (what the
sensor sees), `scene.raycasting_scene()` the same ready for open3d's RaycastingScene with a label and a colour per
geometry id (the simulated sensor uses those for colour and label images). `scene.sdf(points)` is the exact signed
distance to the same geometry (analytic, per shape), for ideal TSDF volumes (`kinfu_cli.sim.tsdf`) and ground-truth
labels (`scene.nearest_labels`).

Layouts: `make_tabletop_scene(seed)` is the synth recording's random tabletop; `primitive_tabletop_scene(seed)` a
tabletop of boxes, cylinders and spheres with one box stacked on another (segmentation tests);
`segmentation_scene(seed)` the segmentation ground-truth tabletop (stacked boxes, touching twins of one colour, a
mug, striped objects) and `scene_label_cloud(scene)` its labelled surface points; `box_scene()` three
boxes on a slab at z = 0 (fusion tests). Any other scene is `Scene(table, (resting_object(...), ...))`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d

from kinfu_cli.core.errors import ConfigError

SHAPES = ("box", "cylinder", "sphere", "torus", "cone")  # the random tabletop's shapes (its draws depend on it)
# a mug: a cylinder body (radius, height) with a handle, a half torus (handle_radius, handle_tube) standing on
# its +x side in the object frame's x-z plane; only the segmentation scenes use it
MUG = "mug"
# a cylinder lying along its object frame's x axis (radius, height = its length along x): parts of composite objects
XCYLINDER = "xcylinder"
# a bowl: a hemispherical shell open at the top (radius of the shell's mid-surface, thickness), a rounded rim
BOWL = "bowl"
# a composite object: the union of `parts` (SceneObjects in the object's frame), one label, a colour per part
COMPOSITE = "composite"

# Distinct, saturated object colours (RGB 0..1); the table is wood-like, the floor grey.
PALETTE = np.array([
    [0.85, 0.15, 0.15], [0.15, 0.55, 0.85], [0.20, 0.70, 0.25], [0.95, 0.75, 0.10],
    [0.60, 0.25, 0.75], [0.95, 0.45, 0.10], [0.10, 0.75, 0.70], [0.85, 0.35, 0.60],
])
TABLE_COLOUR = np.array([0.62, 0.45, 0.28])
FLOOR_COLOUR = np.array([0.45, 0.45, 0.47])

# SceneObject.texture -> the sensor's albedo pattern code (0 plain, 1 the wood-like stripes)
TEXTURE_CODES = {"": 0, "stripes": 1}

# Labels used in label images: 0 = nothing hit, 1 = floor, 2 = table, 3.. = objects in scene order.
LABEL_NONE, LABEL_FLOOR, LABEL_TABLE = 0, 1, 2
# a shape may bulge past its mesh's bounding box by the tessellation's chord height (mm for these meshes); 1 cm
MESH_SLACK = 0.01
# scene_label_cloud only compares distances with -1 mm and 1.5 mm: a part farther than this changes nothing
LABEL_CLOUD_REACH = 0.005


@dataclass(frozen=True)
class Table:
    """A table: top centred at (center[0], center[1], top_z), size (x, y) metres, with four legs (none when
    leg_width is 0 or the top is at floor height)."""

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
        top = _box_mesh(*self._top_box())
        for extents, centre in self._leg_boxes():
            top += _box_mesh(extents, centre)
        top.compute_vertex_normals()
        return top

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m, negative inside) of (..., 3) points to the top and legs."""
        boxes = [self._top_box()] + self._leg_boxes()
        return np.min([_box_sdf(np.asarray(points, dtype=np.float64) - c, np.asarray(e) / 2) for e, c in boxes],
                      axis=0)

    def _top_box(self) -> tuple[tuple, tuple]:
        """(extents, centre) of the top slab."""
        return (self.size[0], self.size[1], self.thickness), (self.center[0], self.center[1],
                                                               self.top_z - self.thickness / 2)

    def _leg_boxes(self) -> list[tuple[tuple, tuple]]:
        """(extents, centre) of each leg, from the floor (z = 0) to the underside of the top."""
        legs_h = self.top_z - self.thickness
        if self.leg_width <= 0 or legs_h <= 0:
            return []
        sx, sy = self.size
        cx, cy = self.center
        inset = 0.06
        return [((self.leg_width, self.leg_width, legs_h),
                 (cx + dx * (sx / 2 - inset), cy + dy * (sy / 2 - inset), legs_h / 2))
                for dx in (-1, 1) for dy in (-1, 1)]

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
    texture: str = ""  # "" plain, "stripes": the sensor's striped albedo (a textured object)
    # COMPOSITE only: the parts (their center and yaw in this object's frame), one ground-truth label for all
    parts: tuple["SceneObject", ...] = ()

    @property
    def footprint_radius(self) -> float:
        """Radius of the circle around the object's x-y centre that covers its footprint."""
        return float(np.hypot(self.size[0], self.size[1]) / 2)

    @property
    def mesh(self) -> o3d.geometry.TriangleMesh:
        """The object's mesh in world coordinates (built on demand)."""
        return _object_mesh(self)

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Exact signed distance (m, negative inside) of (..., 3) world points to the shape (not its mesh)."""
        q = np.asarray(points, dtype=np.float64) - np.asarray(self.center, dtype=np.float64)
        p = self.params
        if self.shape == "sphere":
            return np.linalg.norm(q, axis=-1) - p["radius"]
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        local = np.stack([c * q[..., 0] + s * q[..., 1], -s * q[..., 0] + c * q[..., 1], q[..., 2]], axis=-1)
        if self.shape == "box":
            return _box_sdf(local, np.asarray(self.size, dtype=np.float64) / 2)
        if self.shape == COMPOSITE:  # union of the parts (exact outside; parts overlap, so no hidden faces)
            return np.min([part.sdf(local) for part in self.parts], axis=0)
        if self.shape == BOWL:  # the lower half of a spherical shell: its centre t below the top (rim height)
            r, z = np.hypot(local[..., 1], local[..., 0]), local[..., 2] - (p["radius"] / 2)
            rim = np.hypot(r - p["radius"], z)
            return np.where(z > 0, rim, np.abs(np.hypot(r, z) - p["radius"])) - p["thickness"] / 2
        if self.shape == XCYLINDER:
            d = np.stack([np.hypot(local[..., 1], local[..., 2]) - p["radius"],
                          np.abs(local[..., 0]) - p["height"] / 2], axis=-1)
            return np.linalg.norm(np.maximum(d, 0.0), axis=-1) + np.minimum(d.max(axis=-1), 0.0)
        radial = np.hypot(local[..., 0], local[..., 1])
        if self.shape == "cylinder":
            d = np.stack([radial - p["radius"], np.abs(local[..., 2]) - p["height"] / 2], axis=-1)
            return np.linalg.norm(np.maximum(d, 0.0), axis=-1) + np.minimum(d.max(axis=-1), 0.0)
        if self.shape == "torus":
            return np.hypot(radial - p["torus_radius"], local[..., 2]) - p["tube_radius"]
        if self.shape == "cone":
            return _cone_sdf(radial, local[..., 2], p["radius"], p["height"] / 2)
        if self.shape == MUG:
            d = np.stack([radial - p["radius"], np.abs(local[..., 2]) - p["height"] / 2], axis=-1)
            body = np.linalg.norm(np.maximum(d, 0.0), axis=-1) + np.minimum(d.max(axis=-1), 0.0)
            hx = local[..., 0] - p["radius"]  # handle: torus about the object's y axis, centred on the body's side
            handle = np.hypot(np.hypot(hx, local[..., 2]) - p["handle_radius"], local[..., 1]) - p["handle_tube"]
            return np.minimum(body, handle)
        raise ConfigError(f"unknown shape {self.shape!r}")

    def coloured_meshes(self) -> list[tuple[o3d.geometry.TriangleMesh, np.ndarray, str]]:
        """(world mesh, colour, texture) of each part (the object itself unless it is a composite)."""
        if self.shape != COMPOSITE:
            return [(self.mesh, np.asarray(self.colour), self.texture)]
        return [(_placed(_object_mesh(part), self.yaw, self.center), np.asarray(part.colour), part.texture)
                for part in self.parts]

    def moved_to(self, xy: tuple[float, float], yaw: float | None = None) -> "SceneObject":
        return dataclasses.replace(self, center=(float(xy[0]), float(xy[1]), float(self.center[2])),
                                   yaw=self.yaw if yaw is None else float(yaw))

    def to_json(self) -> dict:
        return {"id": self.id, "shape": self.shape, "center": [float(c) for c in self.center],
                "size": [float(s) for s in self.size], "params": {k: float(v) for k, v in self.params.items()},
                "colour": [float(c) for c in self.colour], "yaw": float(self.yaw),
                **({"texture": self.texture} if self.texture else {}),
                **({"parts": [part.to_json() for part in self.parts]} if self.parts else {})}


@dataclass
class RaycastTarget:
    """An open3d RaycastingScene plus, per geometry id, a label and an RGB albedo (0..1)."""

    scene: o3d.t.geometry.RaycastingScene
    labels: np.ndarray  # (G,) int32
    albedo: np.ndarray  # (G, 3) float
    textured: np.ndarray  # (G,) int: 0 plain, 1 table wood stripes, 2 floor checker, 3 vertex colours
    # (sensor.mesh_target), 4 wallpaper (sim.room.textured_target)
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
        m = _box_mesh(*self._floor_box())
        m.compute_vertex_normals()
        return m

    def _floor_box(self) -> tuple[tuple, tuple]:
        """(extents, centre) of the floor: 4 m square, its top at z = 0."""
        return (4.0, 4.0, 0.02), (self.table.center[0], self.table.center[1], -0.01)

    def mesh(self, include_table: bool = True, include_floor: bool | None = None,
             colours: bool = True) -> o3d.geometry.TriangleMesh:
        """All present geometry as one TriangleMesh in world coordinates (vertex colours when `colours`)."""
        include_floor = self.floor if include_floor is None else include_floor
        parts: list[tuple[o3d.geometry.TriangleMesh, np.ndarray]] = []
        if include_floor:
            parts.append((self.floor_mesh(), FLOOR_COLOUR))
        if include_table:
            parts.append((self.table.mesh(), TABLE_COLOUR))
        parts += [(m, c) for o in self.present_objects for m, c, _ in o.coloured_meshes()]
        out = o3d.geometry.TriangleMesh()
        for m, c in parts:
            if colours:
                m.paint_uniform_color(c)
            out += m
        out.compute_vertex_normals()
        return out

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m, negative inside) of (..., 3) points to the union of the present geometry."""
        return np.min([d for _, d in self._part_distances(points)], axis=0)

    def nearest_labels(self, points: np.ndarray, max_distance: float = np.inf) -> np.ndarray:
        """Label (as in label images) of the present part nearest to each of the (..., 3) points by exact
        distance to its surface; LABEL_NONE where that is farther than `max_distance`."""
        parts = self._part_distances(points)
        dist = np.stack([np.abs(d) for _, d in parts], axis=-1)
        idx = np.argmin(dist, axis=-1)
        labels = np.array([label for label, _ in parts])[idx]
        return np.where(dist.min(axis=-1) <= max_distance, labels, LABEL_NONE)

    def _part_shapes(self) -> list[tuple[int, Callable[[np.ndarray], np.ndarray], Callable[[], tuple]]]:
        """(label, signed distance function of (N, 3) float64 points, its mesh's (min, max) corners, built when
        asked) of the floor (if any), the table and each present object."""
        parts = []
        if self.floor:
            extents, centre = self._floor_box()
            c, half = np.asarray(centre), np.asarray(extents) / 2
            parts.append((LABEL_FLOOR, lambda q: _box_sdf(q - c, half), lambda: (c - half, c + half)))
        table = self.table
        parts.append((LABEL_TABLE, table.sdf, lambda: _mesh_bounds(table.mesh())))
        parts += [(3 + i, o.sdf, lambda o=o: _mesh_bounds(o.mesh)) for i, o in enumerate(self.objects) if o.present]
        return parts

    def _part_distances(self, points: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """(label, signed distance) of the floor (if any), the table and each present object."""
        pts = np.asarray(points, dtype=np.float64)
        return [(label, sdf(pts)) for label, sdf, _ in self._part_shapes()]

    def _part_distances_near(self, points: np.ndarray, reach: float) -> list[tuple[int, np.ndarray]]:
        """_part_distances, exact where a part may lie within `reach` (m) of a point and +inf elsewhere: each part's
        distance is evaluated only inside its mesh's bounding box grown by `reach` and MESH_SLACK (a 4 m floor
        or a wall against every point of the scene was most of scene_label_cloud's time)."""
        pts = np.asarray(points, dtype=np.float64)
        grow = reach + MESH_SLACK
        parts = []
        for label, sdf, bounds in self._part_shapes():
            lo, hi = bounds()
            near = np.flatnonzero(np.all((pts >= np.asarray(lo) - grow) & (pts <= np.asarray(hi) + grow), axis=1))
            d = np.full(len(pts), np.inf)
            d[near] = sdf(pts[near])
            parts.append((label, d))
        return parts

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
                for mesh, colour, texture in o.coloured_meshes():
                    add(mesh, 3 + i, colour, TEXTURE_CODES[texture])
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

def shape_size(shape: str, params: dict) -> tuple[float, float, float]:
    """Axis-aligned extents (x, y, z) in the object frame of a shape with these parameters."""
    p = params
    if shape == "box":
        return float(p["x"]), float(p["y"]), float(p["z"])
    if shape in ("cylinder", "cone"):
        return 2 * p["radius"], 2 * p["radius"], float(p["height"])
    if shape == BOWL:
        outer = p["radius"] + p["thickness"] / 2
        return 2 * outer, 2 * outer, p["radius"] + p["thickness"]
    if shape == XCYLINDER:
        return float(p["height"]), 2 * p["radius"], 2 * p["radius"]
    if shape == "sphere":
        return 2 * p["radius"], 2 * p["radius"], 2 * p["radius"]
    if shape == "torus":
        d = 2 * (p["torus_radius"] + p["tube_radius"])
        return d, d, 2 * p["tube_radius"]
    if shape == MUG:  # symmetric about the body axis, so the handle side sets the x extent on both sides
        return 2 * (p["radius"] + p["handle_radius"] + p["handle_tube"]), 2 * p["radius"], float(p["height"])
    raise ConfigError(f"unknown shape {shape!r}: expected one of {', '.join(SHAPES)}")


def resting_object(object_id: str, shape: str, params: dict, *, xy: tuple[float, float] = (0.0, 0.0),
                   base_z: float = 0.0, yaw: float = 0.0, colour=(0.7, 0.7, 0.7)) -> SceneObject:
    """An object of that shape and parameters (box: x, y, z; cylinder, cone: radius, height; sphere: radius;
    torus: torus_radius, tube_radius) standing at `xy` on a surface at height `base_z`."""
    params = {k: float(v) for k, v in params.items()}
    size = tuple(float(s) for s in shape_size(shape, params))
    return SceneObject(object_id, shape, (float(xy[0]), float(xy[1]), float(base_z + size[2] / 2)), size, params,
                       tuple(float(c) for c in colour), float(yaw))


def random_object(rng: np.random.Generator, object_id: str, shape: str, colour, table: Table) -> SceneObject:
    """An object of that shape with random dimensions (5-16 cm), resting on the table at its centre."""
    yaw = float(rng.uniform(-np.pi, np.pi))
    if shape == "box":
        ext = rng.uniform([0.06, 0.06, 0.06], [0.16, 0.12, 0.16])
        params = {"x": ext[0], "y": ext[1], "z": ext[2]}
    elif shape == "cylinder":
        r, h = rng.uniform(0.03, 0.055), rng.uniform(0.08, 0.18)
        params = {"radius": r, "height": h}
    elif shape == "sphere":
        params = {"radius": rng.uniform(0.035, 0.06)}
    elif shape == "torus":
        R, r = rng.uniform(0.045, 0.065), rng.uniform(0.015, 0.025)
        params = {"torus_radius": R, "tube_radius": r}
    elif shape == "cone":
        r, h = rng.uniform(0.04, 0.06), rng.uniform(0.08, 0.15)
        params = {"radius": r, "height": h}
    else:
        raise ConfigError(f"unknown shape {shape!r}: expected one of {', '.join(SHAPES)}")
    return resting_object(object_id, shape, params, xy=table.center, base_z=table.top_z, yaw=yaw, colour=colour)


def make_tabletop_scene(seed: int = 0, n_objects: int = 4, table: Table | None = None,
                        floor: bool = True) -> Scene:
    """A seeded random tabletop: n_objects of mixed shapes (at least one of box, cylinder, sphere and a mesh).

    Objects are placed without overlap in the central part of the table; ids are "obj1", "obj2", ...
    """
    if n_objects < 0 or n_objects > 12:
        raise ConfigError(f"expected 0..12, got {n_objects}", parameter="n_objects")
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


def primitive_tabletop_scene(seed: int = 0, n_objects: int = 5, stacked: bool = True) -> Scene:
    """A seeded tabletop of boxes, cylinders and spheres 6-16 cm in size, at least 4 cm apart, on the default
    table top (no legs, no floor: nothing below the top), plus (with `stacked`) a smaller box standing on the
    first box: a concave junction that segmentation must cut. Ids "obj1", "obj2", ... (the stacked box last)."""
    table = Table(leg_width=0.0)
    rng = np.random.default_rng(seed)
    objects: list[SceneObject] = []
    placed: list[tuple[np.ndarray, float]] = []
    tries = 0
    while len(objects) < n_objects and tries < 500:
        tries += 1
        label = len(objects) + 1
        shape = ("box", "cylinder", "sphere")[label % 3]
        if shape == "box":
            half = rng.uniform([0.03, 0.03, 0.03], [0.07, 0.06, 0.08])
            params = {"x": 2 * half[0], "y": 2 * half[1], "z": 2 * half[2]}
            foot = float(np.hypot(half[0], half[1]))
        elif shape == "cylinder":
            r = rng.uniform(0.03, 0.05)
            params = {"radius": r, "height": 2 * rng.uniform(0.04, 0.08)}
            foot = float(r)
        else:
            r = rng.uniform(0.035, 0.06)
            params = {"radius": r}
            foot = float(r)
        xy = rng.uniform([-0.45, -0.28], [0.45, 0.28])
        if any(np.linalg.norm(xy - c) < foot + f + 0.04 for c, f in placed):
            continue
        objects.append(resting_object(f"obj{label}", shape, params, xy=xy, base_z=table.top_z,
                                      yaw=float(rng.uniform(0, np.pi)), colour=PALETTE[(label - 1) % len(PALETTE)]))
        placed.append((xy, foot))
    base = next((o for o in objects if o.shape == "box"), None)
    if stacked and base is not None:
        half = np.asarray(base.size) / 2
        top_half = np.array([0.6, 0.6, 0.8]) * half
        centre = np.asarray(base.center) + np.array([0.0, 0.0, half[2] + top_half[2]])
        params = {"x": 2 * top_half[0], "y": 2 * top_half[1], "z": 2 * top_half[2]}
        objects.append(SceneObject(f"obj{len(objects) + 1}", "box", tuple(float(c) for c in centre),
                                   shape_size("box", params), {k: float(v) for k, v in params.items()},
                                   tuple(float(c) for c in PALETTE[len(objects) % len(PALETTE)]), base.yaw + 0.5))
    return Scene(table, tuple(objects), floor=False, seed=seed)


def segmentation_scene(seed: int = 0, table: Table | None = None, floor: bool = True) -> Scene:
    """The segmentation ground-truth tabletop (the "objects" scene of kinfu synth): what colour-free segmentation
    finds hard, each in its own slot of a 3 x 2 grid on the table, slots shuffled and sizes, yaws and places
    jittered by `seed`:

    - stacked boxes ("stack_base" with "stack_top" on it, different colours): a concave junction to cut;
    - two touching boxes of nearly the same colour ("twin_a", "twin_b"), face to face: only the shape's crease
      separates them;
    - a mug with a handle ("mug"): one object of two convex parts that must stay one segment;
    - a striped (textured) box ("textured_box") and a striped cylinder ("textured_can"): colour edges inside one
      object;
    - a sphere on its own ("ball"), free to be picked up by the recording's hand.

    The table's +x end (x > 0.2 m) is left free for the recording's change.
    """
    table = table or Table()
    rng = np.random.default_rng([seed, 4242])
    # five slots for the groups, the ball at the -x end; +x of 0.2 m stays free for the recording's change
    slots = np.array([[-0.12, -0.14], [0.10, -0.14], [-0.12, 0.14], [0.10, 0.14], [-0.34, 0.14]])
    slots = slots[rng.permutation(len(slots))]
    slots = np.vstack([slots, [[-0.36, -0.14]]]) + rng.uniform(-0.02, 0.02, size=(6, 2))
    slots += np.asarray(table.center)
    top = table.top_z
    objects: list[SceneObject] = []

    def jitter(v, rel=0.15):
        return float(v * rng.uniform(1 - rel, 1 + rel))

    # stacked boxes
    yaw = float(rng.uniform(-np.pi, np.pi))
    bx, by, bz = jitter(0.14), jitter(0.11), jitter(0.08)
    base = resting_object("stack_base", "box", {"x": bx, "y": by, "z": bz}, xy=slots[0], base_z=top, yaw=yaw,
                          colour=PALETTE[0])
    objects += [base, resting_object("stack_top", "box", {"x": 0.65 * bx, "y": 0.7 * by, "z": jitter(0.07)},
                                     xy=slots[0], base_z=top + bz, yaw=yaw + float(rng.uniform(0.3, 0.7)),
                                     colour=PALETTE[3])]
    # touching twins of nearly one colour, side by side along their common x axis
    yaw = float(rng.uniform(-np.pi, np.pi))
    ax, bx2 = jitter(0.09), jitter(0.08)
    y_ext, z_a, z_b = jitter(0.10), jitter(0.12), jitter(0.09)
    axis = np.array([np.cos(yaw), np.sin(yaw)])
    centre_a = slots[1] - axis * bx2 / 2
    centre_b = slots[1] + axis * ax / 2
    twin = np.array([0.20, 0.45, 0.80])
    objects += [resting_object("twin_a", "box", {"x": ax, "y": y_ext, "z": z_a}, xy=centre_a, base_z=top, yaw=yaw,
                               colour=twin),
                resting_object("twin_b", "box", {"x": bx2, "y": y_ext, "z": z_b}, xy=centre_b, base_z=top,
                               yaw=yaw, colour=twin + 0.04)]
    # a mug with its handle
    h = jitter(0.10, 0.1)
    objects.append(resting_object(MUG, MUG, {"radius": jitter(0.04, 0.1), "height": h, "handle_radius": 0.28 * h,
                                             "handle_tube": 0.011},
                                  xy=slots[2], base_z=top, yaw=float(rng.uniform(-np.pi, np.pi)),
                                  colour=(0.92, 0.90, 0.82)))
    # textured objects
    objects.append(dataclasses.replace(
        resting_object("textured_box", "box", {"x": jitter(0.12), "y": jitter(0.09), "z": jitter(0.10)},
                       xy=slots[3], base_z=top, yaw=float(rng.uniform(-np.pi, np.pi)), colour=PALETTE[2]),
        texture="stripes"))
    objects.append(dataclasses.replace(
        resting_object("textured_can", "cylinder", {"radius": jitter(0.04, 0.1), "height": jitter(0.13)},
                       xy=slots[4], base_z=top, colour=PALETTE[5]), texture="stripes"))
    objects.append(resting_object("ball", "sphere", {"radius": jitter(0.045, 0.1)}, xy=slots[5], base_z=top,
                                  colour=PALETTE[4]))
    return Scene(table, tuple(objects), floor, seed)


def movable_objects(scene: Scene, clearance: float = 0.01) -> list[SceneObject]:
    """Present objects standing on the table top on their own (nothing on them, no neighbour within
    `clearance` of their footprint circle): the ones a hand may pick up without leaving another floating."""
    out = []
    present = scene.present_objects
    for o in present:
        on_table = abs(o.center[2] - o.size[2] / 2 - scene.table.top_z) < 1e-6
        alone = all(np.linalg.norm(np.subtract(o.center[:2], p.center[:2])) >= o.footprint_radius
                    + p.footprint_radius + clearance for p in present if p is not o)
        if on_table and alone:
            out.append(o)
    return out


def scene_label_cloud(scene: Scene, spacing: float = 0.004, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Per-point object labels of the scene's outer surface: points (N, 3) and labels (N,), 0 for the table
    and the floor (sparser: the table every 1.5 x spacing, the floor's top every 3 x spacing), each present
    object its label-image label (`scene.label_of`, the `label` of changes.json). Surface hidden inside another
    part (a box's bottom on the table, the shared face of touching boxes, the inner half of a mug's handle) is
    left out, so a labelled point is one a sensor could see."""
    from kinfu_cli.sim.sampling import sample_surface  # sampling imports nothing from here; kept local

    parts: list[tuple[int, o3d.geometry.TriangleMesh, float]] = [(0, scene.table.mesh(), 1.5 * spacing)]
    if scene.floor:
        parts.append((0, scene.floor_mesh(), 3 * spacing))
    parts += [(scene.label_of(o.id), o.mesh, spacing) for o in scene.present_objects]
    pts_all, lab_all = [], []
    for k, (label, mesh, step) in enumerate(parts):
        pts, nrm = sample_surface(np.asarray(mesh.vertices), np.asarray(mesh.triangles), step, seed=seed + k)
        if scene.floor and k == 1:  # the floor slab's top face only: nothing sees its sides or underside
            pts = pts[nrm[:, 2] > 0.5]
        pts_all.append(pts)
        lab_all.append(np.full(len(pts), label, dtype=np.int64))
    pts = np.concatenate(pts_all)
    lab = np.concatenate(lab_all)
    # keep points on the union's outer surface: no part (their own included) reaches more than 1 mm beyond them
    dist = scene._part_distances_near(pts, reach=LABEL_CLOUD_REACH)
    inside = np.min([d for _, d in dist], axis=0) < -1e-3
    owner = np.asarray([0 if label in (LABEL_FLOOR, LABEL_TABLE) else label for label, _ in dist])
    # and not on another part's surface (touching faces): another part within 1.5 mm
    other = np.full(len(pts), np.inf)
    for (label, d), own in zip(dist, owner):
        mine = (lab == own)
        other = np.where(mine, other, np.minimum(other, d))
    keep = ~inside & (other > 1.5e-3)
    return pts[keep], lab[keep]


def box_scene() -> Scene:
    """Three boxes (up to 25 cm tall) on a 1.2 m square slab whose top is z = 0, no legs, no floor: a fixed scene
    with exact, easily measured geometry (fusion tests and benchmarks)."""
    table = Table(center=(0.0, 0.0), size=(1.2, 1.2), top_z=0.0, thickness=0.02, leg_width=0.0)
    boxes = [((0.0, 0.0), (0.20, 0.12, 0.15), 0.3), ((0.25, 0.15), (0.10, 0.10, 0.25), -0.5),
             ((-0.22, 0.18), (0.16, 0.08, 0.08), 0.9)]
    objects = tuple(resting_object(f"box{i + 1}", "box", {"x": sx, "y": sy, "z": sz}, xy=xy, yaw=yaw,
                                   colour=PALETTE[i]) for i, (xy, (sx, sy, sz), yaw) in enumerate(boxes))
    return Scene(table, objects, floor=False)


def _mesh_bounds(mesh: o3d.geometry.TriangleMesh) -> tuple[np.ndarray, np.ndarray]:
    """The (min, max) corners of a mesh's axis-aligned bounding box."""
    return mesh.get_min_bound(), mesh.get_max_bound()


# ---- signed distances ---------------------------------------------------------------------------------

def _box_sdf(q: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Signed distance of points q (..., 3), in the box frame, to an axis-aligned box of half-extents `half`."""
    d = np.abs(q) - half
    return np.linalg.norm(np.maximum(d, 0.0), axis=-1) + np.minimum(d.max(axis=-1), 0.0)


def _cone_sdf(radial: np.ndarray, z: np.ndarray, radius: float, half_height: float) -> np.ndarray:
    """Signed distance to a solid cone, base of `radius` at z = -half_height, apex at +half_height, from each
    point's distance to the axis and height (the capped-cone formula of I. Quilez, top radius 0)."""
    h = half_height
    k2 = np.array([-radius, 2 * h])
    ca_r = radial - np.minimum(radial, np.where(z < 0, radius, 0.0))
    ca_z = np.abs(z) - h
    t = np.clip(((-radial) * k2[0] + (h - z) * k2[1]) / (k2 @ k2), 0.0, 1.0)
    cb_r = radial + k2[0] * t
    cb_z = z - h + k2[1] * t
    inside = (cb_r < 0) & (ca_z < 0)
    dist = np.sqrt(np.minimum(ca_r ** 2 + ca_z ** 2, cb_r ** 2 + cb_z ** 2))
    return np.where(inside, -dist, dist)


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
    elif o.shape == XCYLINDER:
        m = o3d.geometry.TriangleMesh.create_cylinder(p["radius"], p["height"], resolution=40)
        m.rotate(np.array([[0, 0, 1.0], [0, 1.0, 0], [-1.0, 0, 0]]), center=(0, 0, 0))  # axis z -> x
    elif o.shape == BOWL:
        m = _bowl_mesh(p["radius"], p["thickness"] / 2)
    elif o.shape == COMPOSITE:
        m = o3d.geometry.TriangleMesh()
        for part in o.parts:  # hidden faces inside other parts: ray casting and the SDF agree on the union
            m += _object_mesh(part)
    elif o.shape == MUG:
        m = o3d.geometry.TriangleMesh.create_cylinder(p["radius"], p["height"], resolution=40)
        handle = o3d.geometry.TriangleMesh.create_torus(p["handle_radius"], p["handle_tube"], radial_resolution=40,
                                                        tubular_resolution=16)
        handle.rotate(np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]), center=(0, 0, 0))  # axis z -> y
        handle.translate((p["radius"], 0.0, 0.0))
        m += handle  # the half inside the body is hidden by it (ray casting and the SDF agree on the union)
    else:
        raise ConfigError(f"unknown shape {o.shape!r}")
    return _placed(m, o.yaw, o.center)


def _bowl_mesh(radius: float, half: float, n_arc: int = 24, n_rim: int = 8, n_around: int = 64
               ) -> o3d.geometry.TriangleMesh:
    """The bowl's surface of revolution (outer arc, rounded rim, inner arc), sphere centre at z = radius / 2."""
    a = np.linspace(-np.pi / 2, 0.0, n_arc)
    rim = np.linspace(0.0, np.pi, n_rim)[1:-1]
    profile = np.concatenate([
        np.stack([(radius + half) * np.cos(a), (radius + half) * np.sin(a)], 1),
        np.stack([radius + half * np.cos(rim), half * np.sin(rim)], 1),
        np.stack([(radius - half) * np.cos(a[::-1]), (radius - half) * np.sin(a[::-1])], 1)])
    phi = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    verts = np.stack([profile[:, None, 0] * np.cos(phi), profile[:, None, 0] * np.sin(phi),
                      np.broadcast_to(profile[:, None, 1] + radius / 2, (len(profile), n_around))], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(len(profile) - 1), np.arange(n_around), indexing="ij")
    a0, a1 = i * n_around + j, i * n_around + (j + 1) % n_around
    b0, b1 = a0 + n_around, a1 + n_around
    tris = np.concatenate([np.stack([a0, a1, b1], -1).reshape(-1, 3), np.stack([a0, b1, b0], -1).reshape(-1, 3)])
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(verts), o3d.utility.Vector3iVector(tris))
    m.remove_degenerate_triangles()
    return m


def _placed(m: o3d.geometry.TriangleMesh, yaw: float, center) -> o3d.geometry.TriangleMesh:
    """The mesh rotated by `yaw` about z, then moved to `center` (object frame -> parent frame)."""
    c, s = np.cos(yaw), np.sin(yaw)
    m.rotate(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), center=(0, 0, 0))
    m.translate(np.asarray(center, dtype=float))
    m.compute_vertex_normals()
    return m
