"""Candidate viewpoints: the paper's viewing sphere around a POI, and candidate pose files.

Sphere sampling (Monica et al. RAS 2016, Sec. NBV): distance d = 0.8 m from the POI, longitude
0-360 deg in 30 deg steps, latitude 0-90 deg in 10 deg steps (upper hemisphere, both ends included),
roll about the optical axis 0-360 deg in 45 deg steps: 12 * 10 * 8 = 960 poses, each looking at the POI.

Poses are 4x4 camera-to-world in the optical convention (z forward, y down). At roll 0 the image x
axis is horizontal (east of the sphere's meridian) and y points down the meridian, so the image is
upright for latitudes below 90 deg. In a world whose up is not z the sphere is turned by the smallest
rotation taking z to up (fusion.up.z_to_up_rotation): latitudes count from the plane across up. Poses are
ordered position-major (all rolls of one sphere
position are consecutive), which lets the ray caster share the rays of the rolls.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import check_up
from kinfu_cli.core.poses import check_poses
from kinfu_cli.fusion.up import z_to_up_rotation


@dataclass(frozen=True)
class SphereSpec:
    """The viewing sphere around a POI; the defaults are the paper's (960 poses). Angles in degrees."""

    radius: float = 0.8  # distance d of the sensor from the POI (m)
    lon_step: float = 30.0
    lat_min: float = 0.0
    lat_max: float = 90.0
    lat_step: float = 10.0
    roll_step: float = 45.0

    def view_count(self) -> int:
        """Number of poses `viewpoints` makes (ConfigError beyond MAX_SPHERE_VIEWS), without making them."""
        return sphere_view_count(self.lon_step, self.lat_min, self.lat_max, self.lat_step, self.roll_step)

    def viewpoints(self, center, up=None) -> np.ndarray:
        """(N, 4, 4) camera-to-world poses on this sphere around `center` (see `sphere_viewpoints`)."""
        return sphere_viewpoints(center, **asdict(self), up=up)

    def to_json(self) -> dict:
        return asdict(self)


PAPER_SPHERE = SphereSpec()


def _angle_count(start: float, stop: float, step: float, *, closed: bool, name: str) -> int:
    """How many angles `_angles` returns, computed without making them (a tiny step would fill the memory)."""
    if not 0 < step <= 360:  # also refuses NaN and inf
        raise ConfigError(f"expected a step in (0, 360] degrees, got {step}", parameter=f"{name}_step")
    if stop < start:
        raise ConfigError(f"expected min <= max, got {start} > {stop}", parameter=f"{name}_min/{name}_max")
    n = int(math.floor((stop - start) / step + 1e-9))
    if not closed and n > 0 and np.isclose(step * n, 360.0):
        return n  # 360 is 0 again
    return n + 1


def _angles(start: float, stop: float, step: float, *, closed: bool, name: str) -> np.ndarray:
    n = _angle_count(start, stop, step, closed=closed, name=name)
    return start + step * np.arange(n)


# Most candidate views one viewing sphere may hold: ~100 x the paper's 960. A candidate costs ~1.2 kB of peak memory
# through `kinfu nbv` (its pose, sphere temporaries, scores and, with --top 0, its listed view; measured 450 MB for
# 2 x 96,000) and ~0.1 ms, so the limit keeps a POI near 0.1 GB and 10-20 s, where a 0.01 deg step took 1.7 GB.
MAX_SPHERE_VIEWS = 100_000
# Most candidate views one run may rank over all its POIs (each POI gets its own sphere, all made up front): at the
# same ~1.2 kB a candidate that is ~1.2 GB of peak memory and 2-7 min of casting (0.1-0.4 ms a view, the latter
# measured on the sample's POIs); 1,000 POIs at the paper's 960 views, or 10 spheres at MAX_SPHERE_VIEWS. 2,000
# POIs made 1.9 M poses and a run of many minutes.
MAX_RUN_VIEWS = 1_000_000


def sphere_view_count(lon_step: float = PAPER_SPHERE.lon_step, lat_min: float = PAPER_SPHERE.lat_min,
                      lat_max: float = PAPER_SPHERE.lat_max, lat_step: float = PAPER_SPHERE.lat_step,
                      roll_step: float = PAPER_SPHERE.roll_step) -> int:
    """Number of poses `sphere_viewpoints` makes with these angles; ConfigError naming the steps when it exceeds
    MAX_SPHERE_VIEWS (checked before any pose is made)."""
    if not (-90 <= lat_min <= lat_max <= 90):
        raise ConfigError(f"expected -90 <= min <= max <= 90, got {lat_min}, {lat_max}", parameter="lat_min/lat_max")
    n_lon = _angle_count(0.0, 360.0, lon_step, closed=False, name="lon")
    n_lat = _angle_count(lat_min, lat_max, lat_step, closed=True, name="lat")
    n_roll = _angle_count(0.0, 360.0, roll_step, closed=False, name="roll")
    total = n_lon * n_lat * n_roll
    if total > MAX_SPHERE_VIEWS:
        def num(n: int) -> str:
            return f"{n:,}" if n < 10 ** 12 else f"~{str(n)[0]}e{len(str(n)) - 1}"
        raise ConfigError(f"the viewing sphere would hold {num(total)} candidate views ({num(n_lon)} longitudes x "
                          f"{num(n_lat)} latitudes x {num(n_roll)} rolls), more than the {MAX_SPHERE_VIEWS:,} allowed "
                          f"(the paper's sphere holds 960); use larger steps or a narrower latitude range",
                          parameter="lon_step/lat_step/roll_step")
    return total


MIN_RADIUS_M, MAX_RADIUS_M = 0.01, 100.0  # viewing sphere radius


def sphere_viewpoints(center, radius: float = PAPER_SPHERE.radius, lon_step: float = PAPER_SPHERE.lon_step,
                      lat_min: float = PAPER_SPHERE.lat_min, lat_max: float = PAPER_SPHERE.lat_max,
                      lat_step: float = PAPER_SPHERE.lat_step, roll_step: float = PAPER_SPHERE.roll_step,
                      up=None) -> np.ndarray:
    """(N, 4, 4) camera-to-world poses on a sphere of `radius` around `center`, all looking at it.

    Longitudes in [0, 360), latitudes in [lat_min, lat_max] inclusive, rolls in [0, 360).
    Order: longitude, latitude, roll (roll fastest). up: the world's up direction (None: z); the sphere
    built about z is turned onto it.
    """
    center = np.asarray(center, dtype=np.float64).reshape(3)
    if not (MIN_RADIUS_M <= radius <= MAX_RADIUS_M):  # also refuses NaN; farther or nearer hangs the ray caster
        raise ConfigError(f"expected a distance in [{MIN_RADIUS_M:g}, {MAX_RADIUS_M:g}] m, got {radius}",
                          parameter="radius")
    sphere_view_count(lon_step, lat_min, lat_max, lat_step, roll_step)
    lons = np.radians(_angles(0.0, 360.0, lon_step, closed=False, name="lon"))
    lats = np.radians(_angles(lat_min, lat_max, lat_step, closed=True, name="lat"))
    rolls = np.radians(_angles(0.0, 360.0, roll_step, closed=False, name="roll"))
    lon, lat, roll = (a.ravel() for a in np.meshgrid(lons, lats, rolls, indexing="ij"))
    radial = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=1)
    z = -radial
    x0 = np.stack([-np.sin(lon), np.cos(lon), np.zeros_like(lon)], axis=1)  # east, horizontal
    y0 = np.cross(z, x0)
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x = c * x0 + s * y0
    y = -s * x0 + c * y0
    T = np.zeros((lon.size, 4, 4))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2] = x, y, z
    T[:, :3, 3] = radius * radial
    T[:, 3, 3] = 1.0
    if up is not None:
        R = z_to_up_rotation(check_up(up, "up"))
        T[:, :3, :] = np.einsum("ij,njk->nik", R, T[:, :3, :])
    T[:, :3, 3] += center
    return T


def read_candidates(path: str | os.PathLike) -> np.ndarray:
    """Read a candidate file: a JSON list of 4x4 camera-to-world poses, or {"poses": [...]}
    (entries may also be objects with a "pose" key, as in views.json)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such candidate file") from None
    except (OSError, ValueError) as exc:  # JSONDecodeError, UnicodeDecodeError, an integer of > 4300 digits
        raise ConfigError(f"{path}: not a JSON candidate file ({exc}); expected a list of 4x4 poses") from None
    except RecursionError:
        raise ConfigError(f"{path}: JSON nested too deeply to read; expected a list of 4x4 poses") from None
    if isinstance(doc, dict):
        doc = doc.get("poses", doc.get("candidates"))
    if not isinstance(doc, list):
        raise ConfigError(f"{path}: expected a JSON list of 4x4 poses or {{\"poses\": [...]}}")
    doc = [d["pose"] if isinstance(d, dict) and "pose" in d else d for d in doc]
    try:
        arr = np.asarray(doc, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{path}: expected a list of 4x4 numeric poses") from None
    return check_poses(arr, source=str(path))
