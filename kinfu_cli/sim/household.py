"""YCB-like household objects as composites of primitives, and the seeded `household_scene` tabletop.

Real household objects have parts that a segmentation may split: a drill's handle and battery base, a bottle's
shoulder, neck and a cap of another colour, printed boxes and cans with large colour blocks. Each object here is
one `SceneObject` of shape COMPOSITE: its parts (boxes, vertical and horizontal cylinders, cones, a bowl shell)
share one ground-truth label and keep their own colours. Parts overlap by at least 1.5 mm, so no face hidden
inside the union is taken for a visible one (`scene_label_cloud` drops points more than 1 mm inside a part).
Printed colour blocks are plates 2 mm thick standing 0.5 mm proud of the face (far below depth noise): the sensor
then sees the plate's colour and the body's face under it is hidden.

Sizes follow the YCB object set (Calli et al. 2015), rounded: mustard bottle, bleach cleanser, power drill,
cracker box, sugar box, gelatin box, tomato soup can, master chef can, mug, bowl.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.scene import (BOWL, COMPOSITE, MUG, XCYLINDER, Scene, SceneObject, Table, _object_mesh,
                                 resting_object)

PLATE = 0.002  # printed block thickness; 0.5 mm of it stands proud of the face
PROUD = 0.0005
BLACK, WHITE = (0.12, 0.12, 0.13), (0.92, 0.91, 0.88)


def _part(shape: str, params: dict, x: float, y: float, bottom: float, colour, yaw: float = 0.0) -> SceneObject:
    """A part standing with its lowest point at height `bottom` above (x, y) of the object's base frame."""
    return resting_object("part", shape, params, xy=(x, y), base_z=bottom, yaw=yaw, colour=colour)


def _plates(size, blocks) -> list[SceneObject]:
    """Printed blocks on a box of `size` (x, y, z) standing at the origin: (face, u0, u1, z0, z1, colour) with
    face one of +x -x +y -y +z, u along the face's horizontal (its other axis for +z: z0, z1 along y)."""
    sx, sy, sz = size
    out = []
    for face, u0, u1, z0, z1, colour in blocks:
        out_off = PROUD - PLATE / 2  # the plate's centre from the face, outwards
        if face == "+z":
            p = {"x": u1 - u0, "y": z1 - z0, "z": PLATE}
            out.append(_part("box", p, (u0 + u1) / 2, (z0 + z1) / 2, sz + PROUD - PLATE, colour))
            continue
        sign = 1.0 if face[0] == "+" else -1.0
        if face[1] == "x":
            p, xy = {"x": PLATE, "y": u1 - u0, "z": z1 - z0}, (sign * (sx / 2 + out_off), (u0 + u1) / 2)
        else:
            p, xy = {"x": u1 - u0, "y": PLATE, "z": z1 - z0}, ((u0 + u1) / 2, sign * (sy / 2 + out_off))
        out.append(_part("box", p, xy[0], xy[1], z0, colour))
    return out


def _bottle(body_r: float, body_h: float, shoulder_h: float, neck_r: float, neck_h: float, cap_r: float,
            cap_h: float, colour, cap_colour, body_box: tuple | None = None) -> list[SceneObject]:
    """Body (a cylinder, or a box of (x, y)), a cone shoulder, a neck and a cap of its own colour."""
    body = (_part("box", {"x": body_box[0], "y": body_box[1], "z": body_h}, 0, 0, 0, colour) if body_box else
            _part("cylinder", {"radius": body_r, "height": body_h}, 0, 0, 0, colour))
    top = body_h + shoulder_h * 0.55
    return [body,
            _part("cone", {"radius": body_r, "height": shoulder_h}, 0, 0, body_h - 0.003, colour),
            _part("cylinder", {"radius": neck_r, "height": top + neck_h - body_h}, 0, 0, body_h, colour),
            _part("cylinder", {"radius": cap_r, "height": cap_h}, 0, 0, top + neck_h - 0.003, cap_colour)]


def _drill() -> list[SceneObject]:
    """Standing on its battery: black battery base, teal handle, horizontal teal barrel, black chuck."""
    teal = (0.10, 0.55, 0.55)
    barrel_z = 0.150
    return [_part("box", {"x": 0.11, "y": 0.075, "z": 0.05}, 0.0, 0.0, 0.0, BLACK),
            _part("box", {"x": 0.04, "y": 0.036, "z": barrel_z - 0.045 + 0.01}, -0.015, 0.0, 0.045, teal),
            _part(XCYLINDER, {"radius": 0.031, "height": 0.16}, 0.03, 0.0, barrel_z, teal),
            _part(XCYLINDER, {"radius": 0.017, "height": 0.048}, 0.03 + 0.08 + 0.021, 0.0, barrel_z + 0.014, BLACK)]


def _can(radius: float, height: float, colour, label_colour, label_from: float) -> list[SceneObject]:
    """A metal can with a label sleeve (0.5 mm proud) of another colour over the upper part of its side."""
    lo, hi = label_from * height, height - 0.008
    return [_part("cylinder", {"radius": radius, "height": height}, 0, 0, 0, colour),
            _part("cylinder", {"radius": radius + PROUD, "height": hi - lo}, 0, 0, lo, label_colour)]


def _box(size, colour, blocks) -> list[SceneObject]:
    return [_part("box", {"x": size[0], "y": size[1], "z": size[2]}, 0, 0, 0, colour)] + _plates(size, blocks)


def _bowl(radius: float, colour) -> list[SceneObject]:
    """A shell on a foot ring; the shell's bottom sinks 4 mm into the foot."""
    t = 0.006
    return [_part("cylinder", {"radius": 0.3 * radius, "height": 0.008}, 0, 0, 0, colour),
            _part(BOWL, {"radius": radius, "thickness": t}, 0, 0, 0.004, colour)]


def _parts_of(kind: str) -> list[SceneObject]:
    """The parts of one household object kind in its base frame (z = 0 on the table)."""
    yellow, red, blue = (0.95, 0.78, 0.10), (0.80, 0.12, 0.10), (0.15, 0.30, 0.75)
    if kind == "mustard":
        return _bottle(0.033, 0.125, 0.045, 0.011, 0.018, 0.014, 0.022, yellow, red)
    if kind == "bleach":
        return _bottle(0.032, 0.165, 0.04, 0.015, 0.012, 0.018, 0.022, WHITE, blue, body_box=(0.095, 0.064)) + \
            _plates((0.095, 0.064, 0.165), [("+y", -0.04, 0.04, 0.04, 0.13, blue), ("-y", -0.04, 0.04, 0.04, 0.13,
                                                                                      blue)])
    if kind == "drill":
        return _drill()
    if kind == "cracker_box":
        size = (0.16, 0.06, 0.21)
        return _box(size, red, [("+y", -0.07, 0.07, 0.01, 0.11, yellow), ("+y", -0.07, -0.01, 0.14, 0.20, WHITE),
                                ("-y", -0.07, 0.07, 0.01, 0.11, yellow), ("+x", -0.025, 0.025, 0.01, 0.11, yellow),
                                ("-x", -0.025, 0.025, 0.01, 0.11, yellow)])
    if kind == "sugar_box":
        size = (0.09, 0.045, 0.175)
        return _box(size, WHITE, [("+y", -0.04, 0.04, 0.10, 0.17, yellow), ("-y", -0.04, 0.04, 0.10, 0.17, yellow),
                                  ("+y", -0.04, 0.01, 0.01, 0.06, blue), ("-y", -0.04, 0.01, 0.01, 0.06, blue)])
    if kind == "gelatin_box":
        size = (0.085, 0.073, 0.028)
        return _box(size, red, [("+z", -0.035, 0.02, -0.03, 0.03, WHITE), ("+y", -0.035, 0.035, 0.005, 0.02,
                                                                                 WHITE)])
    if kind == "soup_can":
        return _can(0.033, 0.101, WHITE, red, 0.5)
    if kind == "chef_can":
        return _can(0.051, 0.14, (0.70, 0.70, 0.72), blue, 0.12)
    if kind == "bowl":
        return _bowl(0.075, red)
    raise ConfigError(f"expected one of {', '.join(KINDS)}, got {kind!r}", parameter="kind")


KINDS = ("mustard", "bleach", "drill", "cracker_box", "sugar_box", "gelatin_box", "soup_can", "chef_can", "bowl",
         "mug")


def household_object(object_id: str, kind: str, xy=(0.0, 0.0), base_z: float = 0.0, yaw: float = 0.0
                     ) -> SceneObject:
    """One household object of that kind standing at `xy` on a surface at `base_z` (a MUG for "mug", else a
    COMPOSITE whose parts are re-centred on their bounding box)."""
    if kind == "mug":
        return resting_object(object_id, MUG, {"radius": 0.04, "height": 0.09, "handle_radius": 0.026,
                                               "handle_tube": 0.009}, xy=xy, base_z=base_z, yaw=yaw,
                              colour=(0.80, 0.12, 0.10))
    parts = _parts_of(kind)
    verts = np.concatenate([np.asarray(_object_mesh(p).vertices) for p in parts])
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    mid = (lo + hi) / 2
    parts = tuple(p.moved_to((p.center[0] - mid[0], p.center[1] - mid[1])) for p in parts)
    parts = tuple(SceneObject(p.id, p.shape, (p.center[0], p.center[1], p.center[2] - mid[2]), p.size, p.params,
                              p.colour, p.yaw) for p in parts)
    size = tuple(float(s) for s in hi - lo)
    return SceneObject(object_id, COMPOSITE, (float(xy[0]), float(xy[1]), float(base_z + size[2] / 2)), size, {},
                       parts[0].colour, float(yaw), parts=parts)


def household_scene(seed: int = 0, table: Table | None = None, floor: bool = True, n_objects: int | None = None
                    ) -> Scene:
    """A seeded tabletop of 5-11 household objects (`n_objects` to fix the count), kinds drawn so that the first
    ones cover the set, yaws random, placed (largest first) without overlap 2 cm apart; ids "<kind>" or "<kind>_<k>"."""
    table = table or Table()
    rng = np.random.default_rng([seed, 5151])
    n = int(rng.integers(5, 12)) if n_objects is None else int(n_objects)
    if not 1 <= n <= 11:
        raise ConfigError(f"expected 1..11, got {n}", parameter="n_objects")
    kinds = [KINDS[i] for i in rng.permutation(len(KINDS))]
    kinds = (kinds + [KINDS[i] for i in rng.integers(0, len(KINDS), size=n)])[:n]
    seen: dict[str, int] = {}
    objects = []
    for kind in kinds:
        seen[kind] = seen.get(kind, 0) + 1
        oid = kind if seen[kind] == 1 else f"{kind}_{seen[kind]}"
        objects.append(household_object(oid, kind, base_z=table.top_z, yaw=float(rng.uniform(-np.pi, np.pi))))
    scene = Scene(table, (), floor, seed)
    for obj in sorted(objects, key=lambda o: -o.footprint_radius):  # the large ones first: they always fit
        xy = scene.free_spot(rng, obj.footprint_radius, margin=0.06, clearance=0.02)
        scene = scene.with_change("placement", obj, xy)
    return scene


def object_kind(object_id: str) -> str:
    """The kind of a household object from its id ("soup_can_2" -> "soup_can")."""
    base, _, tail = object_id.rpartition("_")
    return base if base and tail.isdigit() else object_id



