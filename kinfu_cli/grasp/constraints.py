"""What a grasp pose must satisfy (thesis eqs. 7.5-7.10, 8.2): the support plane, a workspace box per hand,
up to three orientation cones (one per hand axis) and, for multi-part objects, staying outside the other
parts. Infeasible settings are refused before any optimisation (`check_feasible`).

Cone (7.8-7.10): the hand axis `axis` (x, y or z of the hand frame, see `hand`) must lie within `aperture_deg`
of the unit direction `direction`: axis . direction - cos(aperture) >= 0. Presets, with `up` the support
plane's normal: "top" = approach z_h within the aperture of -up; "side" = y_h (across the palm) within the
aperture of +up, so the approach is near horizontal and the palm spans the object's height.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.errors import ConfigError

AXES = "xyz"
PRESET_APERTURE_DEG = 30.0


@dataclass(frozen=True)
class Cone:
    """Hand axis `axis` ('x', 'y' or 'z') within `aperture_deg` of `direction` (world, normalised here)."""

    axis: str
    direction: tuple[float, float, float]
    aperture_deg: float

    def unit(self) -> np.ndarray:
        d = np.asarray(self.direction, dtype=np.float64)
        return d / np.linalg.norm(d)


def preset_cone(name: str, up: np.ndarray, aperture_deg: float = PRESET_APERTURE_DEG) -> Cone:
    """'top' or 'side' (module docstring) for the support plane normal `up`."""
    up = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    if name == "top":
        return Cone("z", tuple(-up), aperture_deg)
    if name == "side":
        return Cone("y", tuple(up), aperture_deg)
    raise ConfigError(f"expected 'top', 'side' or 'AXIS:dx,dy,dz:deg', got {name!r}", parameter="cones")


@dataclass(frozen=True)
class Workspace:
    """Box the palm centre must stay in (eq. 7.7), `low` / `high` (3,) world metres; its centre is the
    reachability proxy's target (real inverse kinematics is the robot's job)."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]

    def center(self) -> np.ndarray:
        return (np.asarray(self.low) + np.asarray(self.high)) / 2

    def to_json(self) -> dict:
        return {"low": [float(v) for v in self.low], "high": [float(v) for v in self.high]}


@dataclass
class GraspConstraints:
    """Support plane (a, b, c, d) with unit normal towards the objects (None: no plane), workspace box,
    orientation cones (at most one per hand axis)."""

    plane: np.ndarray | None
    workspace: Workspace | None = None
    cones: list[Cone] = field(default_factory=list)


def check_cones(cones: list[Cone]) -> None:
    """ConfigError for more than three cones, two on one axis, a bad aperture or zero direction, or a pair
    of cones that no rotation can satisfy (the two hand axes are perpendicular: the angle between the cone
    directions must be within 90 deg +- the sum of apertures)."""
    if len(cones) > 3:
        raise ConfigError(f"at most three orientation cones (one per hand axis), got {len(cones)}", parameter="cones")
    seen = set()
    for c in cones:
        if c.axis not in AXES:
            raise ConfigError(f"cone axis must be x, y or z, got {c.axis!r}", parameter="cones")
        if c.axis in seen:
            raise ConfigError(f"two cones on hand axis {c.axis}", parameter="cones")
        seen.add(c.axis)
        if not 0.0 < c.aperture_deg <= 180.0:
            raise ConfigError(f"cone aperture must be in (0, 180] deg, got {c.aperture_deg}", parameter="cones")
        d = np.asarray(c.direction, dtype=np.float64)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-9:
            raise ConfigError(f"cone direction must be a non-zero 3-vector, got {c.direction}", parameter="cones")
    for i, a in enumerate(cones):
        for b in cones[i + 1:]:
            ang = np.degrees(np.arccos(np.clip(a.unit() @ b.unit(), -1, 1)))
            slack = a.aperture_deg + b.aperture_deg
            if abs(ang - 90.0) > slack:
                raise ConfigError(
                    f"infeasible orientation cones: hand axes {a.axis} and {b.axis} are perpendicular, but their "
                    f"cone directions are {ang:.0f} deg apart with apertures {a.aperture_deg:g} + "
                    f"{b.aperture_deg:g} deg", parameter="cones")


def check_workspace(ws: Workspace, plane: np.ndarray | None, name: str = "workspace") -> None:
    """ConfigError for an empty box or one wholly on the wrong side of the support plane."""
    lo, hi = np.asarray(ws.low, dtype=np.float64), np.asarray(ws.high, dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ConfigError(f"expected six finite numbers, got {ws.low} .. {ws.high}", parameter=name)
    if np.any(lo >= hi):
        raise ConfigError(f"infeasible workspace: empty box, low {lo.tolist()} not below high {hi.tolist()}",
                          parameter=name)
    if plane is not None:
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        h = corners @ plane[:3] + plane[3]
        if h.max() <= 0:
            raise ConfigError(f"infeasible workspace: the whole box is below the support plane (highest corner "
                              f"{h.max():.3f} m)", parameter=name)


def default_workspaces(centers: np.ndarray, up: np.ndarray, margin: float = 0.3) -> dict[str, Workspace]:
    """Per-hand boxes when none is given: the objects' bounding box grown by `margin`, split across the
    world's second horizontal axis (the robot is assumed to face +x: right hand -y side, left +y side, with
    an overlap of `margin` / 2 in the middle)."""
    lo = centers.min(axis=0) - margin
    hi = centers.max(axis=0) + margin
    mid = (lo[1] + hi[1]) / 2
    right = Workspace(tuple(lo), (hi[0], mid + margin / 2, hi[2]))
    left = Workspace((lo[0], mid - margin / 2, lo[2]), tuple(hi))
    return {"right": right, "left": left}


def parse_cone(text: str, up: np.ndarray, aperture_deg: float = PRESET_APERTURE_DEG) -> Cone:
    """'top', 'side' or 'AXIS:dx,dy,dz:deg' (e.g. 'z:0,0,-1:30')."""
    text = text.strip()
    if text in ("top", "side"):
        return preset_cone(text, up, aperture_deg)
    parts = text.split(":")
    if len(parts) == 3 and any(not v.strip() for v in parts[1].split(",")):
        raise ConfigError(f"{text!r}: an empty item in the cone's direction; expected comma-separated values "
                          f"without gaps", parameter="cones")
    try:
        axis, d, ang = parts
        direction = tuple(float(v) for v in d.split(","))
        cone = Cone(axis.strip(), direction, float(ang))  # type: ignore[arg-type]
    except ValueError:
        raise ConfigError(f"expected 'top', 'side' or 'AXIS:dx,dy,dz:deg', got {text!r}", parameter="cones") from None
    if len(cone.direction) != 3:
        raise ConfigError(f"cone direction needs three numbers, got {text!r}", parameter="cones")
    return cone
