"""A room's structure: the large planes that bound the scene (floor, walls, ceiling), with a band that follows
their own noise.

A fused room is seen from 3-4 m, where the Kinect's depth noise (sigma 2-3 cm) is several times the 1 cm
support-plane band, so the floor and the walls leave a bumpy layer of points off their planes whose normals
point anywhere (median |n . plane normal| 0.5-0.75 on the synthetic room). LCCP then links walls through
those points and into the furniture that stands against them, and cuts the layer into hundreds of patches.

1. Planes: RANSAC (`ransac_plane`) on the cloud thinned to one point per STRUCT_CELL cell, up to
   `max_planes` rounds (fewer after STRUCT_MAX_MISSES planes in a row that are no structure), inlier distance
   STRUCT_RANSAC_DISTANCE (about the far wall's noise).
2. A plane is structure when it bounds the scene and is room-sized: no more than STRUCT_MAX_BEHIND of the
   points lie more than STRUCT_BEHIND behind it (a table top has its legs and the floor below it, a shelf's
   front the wall behind it), and its inliers span at least `min_extent` in both directions of the plane
   (5-95 % percentiles). It faces the side holding the points.
3. The scene is a room only with two such planes at least STRUCT_MIN_ANGLE_DEG apart (a floor and a wall, or
   two walls); otherwise nothing is structure. A tabletop scene whose volume holds the floor under the table
   (one bounding plane) keeps its single support plane as before.
4. Band: per STRUCT_TILE square of the plane, the median and the robust spread (1.4826 x MAD) of the
   residuals of the points within STRUCT_WINDOW whose normals lean towards the plane's (within
   STRUCT_NORMAL_DEG); the band is the median +- `sigmas` x spread (at least `min_band`, at most
   STRUCT_MAX_BAND), so it widens with the range the surface was seen from. Points behind the band (within
   STRUCT_WINDOW) are the plane's too: nothing stands behind a wall. A tile with fewer than STRUCT_TILE_POINTS
   such points has no band (an opening, a plane's extension beyond the room).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.neighbours import grid_cells
from kinfu_cli.core.poses import plane_axes
from kinfu_cli.segmentation.group_stats import group_percentile
from kinfu_cli.segmentation.plane_ransac import ransac_plane

STRUCT_CELL = 0.05  # thinning for the plane search (m): a 5 x 4 m room's surfaces in ~50 k points
STRUCT_RANSAC_DISTANCE = 0.03  # inlier distance of the search (m): about the noise of a wall seen from 4 m
STRUCT_MIN_SHARE = 0.02  # the search stops at a plane holding less than this share of the thinned points
STRUCT_MAX_MISSES = 2  # ... or after this many planes in a row that are no structure: a room's floor and walls
# are its largest planes (the synthetic rooms' five came first, before the shelf's front and the sofa's seat)
STRUCT_BEHIND = 0.1  # a point this far behind a plane (m) is behind it, not noise
STRUCT_MAX_BEHIND = 0.01  # share of the points a bounding plane may have behind it
STRUCT_MIN_ANGLE_DEG = 45.0  # a room has two bounding planes at least this far apart (a floor and a wall)
STRUCT_DUPLICATE_DEG = 10.0  # a plane this parallel to a structural one and within STRUCT_WINDOW of it is its noise
STRUCT_TILE = 0.5  # side of the squares the band is estimated over (m)
STRUCT_WINDOW = 0.1  # residuals within this of the plane estimate its band (m)
STRUCT_NORMAL_DEG = 60.0  # points estimating the band lean towards the plane's normal within this
STRUCT_TILE_POINTS = 30  # fewer estimating points in a tile: no band there
STRUCT_MAX_BAND = 0.06  # the band's half width is at most this (m)


@dataclass
class Structure:
    """planes (K, 4), each a, b, c, d with the unit normal facing into the scene; mask (N,) the points on
    them; reach (N,) a point's distance past the nearest plane's band edge in band half-widths (0 on or behind
    a band, inf with no band there); height (N,) the point's height over that plane's local median (m, nan with
    no band); info: what the search saw (JSON-ready)."""

    planes: np.ndarray
    mask: np.ndarray
    reach: np.ndarray
    height: np.ndarray
    info: dict = field(default_factory=dict)


def _extents(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """5-95 % spans of points along the principal axes of their projection on the plane (2,), largest first."""
    uv = (points - points.mean(axis=0)) @ plane_axes(normal).T
    if len(uv) < 3:
        return np.zeros(2)
    _, vec = np.linalg.eigh(np.cov(uv.T))
    uv = uv @ vec[:, ::-1]
    return np.quantile(uv, 0.95, axis=0) - np.quantile(uv, 0.05, axis=0)


def bounding_planes(points: np.ndarray, max_planes: int, min_extent: float, iterations: int,
                    rng: np.random.Generator) -> tuple[list[np.ndarray], dict]:
    """(planes facing into the scene, info): steps 1-2 of the module docstring."""
    sub = points[grid_cells(points, STRUCT_CELL)[0]]
    info: dict = {"thinned_points": int(len(sub)), "planes_tried": 0, "rejected": []}
    found: list[np.ndarray] = []
    remaining = np.arange(len(sub))
    misses = 0
    for _ in range(max_planes):
        if len(remaining) < max(3, STRUCT_MIN_SHARE * len(sub)) or misses >= STRUCT_MAX_MISSES:
            break
        plane, inl = ransac_plane(sub[remaining], STRUCT_RANSAC_DISTANCE, iterations, rng)
        if len(inl) < STRUCT_MIN_SHARE * len(sub):
            break
        info["planes_tried"] += 1
        inl_pts = sub[remaining[inl]]
        remaining = np.delete(remaining, inl)
        dist = sub @ plane[:3] + plane[3]
        if np.sum(dist < -STRUCT_BEHIND) > np.sum(dist > STRUCT_BEHIND):
            plane, dist = -plane, -dist
        behind = float(np.mean(dist < -STRUCT_BEHIND))
        ext = _extents(inl_pts, plane[:3])
        dup = any(abs(plane[:3] @ f[:3]) >= np.cos(np.radians(STRUCT_DUPLICATE_DEG))
                  and abs(np.mean(inl_pts @ f[:3]) + f[3]) < STRUCT_WINDOW for f in found)
        if behind <= STRUCT_MAX_BEHIND and ext.min() >= min_extent and not dup:
            found.append(plane)
            misses = 0
        else:
            misses += 1
            info["rejected"].append({"round": info["planes_tried"], "normal": [round(float(v), 3) for v in plane[:3]],
                                     "behind": round(behind, 4), "extent": [round(float(v), 2) for v in ext],
                                     "duplicate": bool(dup)})
    return found, info


def _plane_band(points: np.ndarray, normals: np.ndarray, plane: np.ndarray, sigmas: float, min_band: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per point, (how far past the plane's band edge it lies in band half-widths (module docstring, step 4):
    <= 1 inside the band, 0 behind it, inf outside STRUCT_WINDOW or in a tile without a band; its height over
    the tile's median, nan where the first is inf)."""
    dist = points @ plane[:3] + plane[3]
    out = np.full(len(points), np.inf)
    height = np.full(len(points), np.nan)
    win = np.flatnonzero(np.abs(dist) < STRUCT_WINDOW)
    if len(win) == 0:
        return out, height
    uv = np.floor(points[win] @ plane_axes(plane[:3]).T / STRUCT_TILE).astype(np.int64)
    uv -= uv.min(axis=0)
    tiles, tile = np.unique(uv[:, 0] * (uv[:, 1].max() + 1) + uv[:, 1], return_inverse=True)
    k = len(tiles)
    est = np.abs(normals[win] @ plane[:3]) >= np.cos(np.radians(STRUCT_NORMAL_DEG))
    d_est, t_est = dist[win][est], tile[est]
    med = group_percentile(d_est, t_est, k, 50)
    sigma = 1.4826 * group_percentile(np.abs(d_est - med[t_est]), t_est, k, 50)
    half = np.clip(sigmas * sigma, min_band, STRUCT_MAX_BAND)
    ok = np.bincount(t_est, minlength=k) >= STRUCT_TILE_POINTS
    r = (dist[win] - med[tile]) / half[tile]
    out[win] = np.where(ok[tile], np.maximum(r, 0.0), np.inf)
    height[win] = np.where(ok[tile], dist[win] - med[tile], np.nan)
    return out, height


def find_structure(points: np.ndarray, normals: np.ndarray, *, max_planes: int, min_extent: float, sigmas: float,
                   min_band: float, iterations: int, rng: np.random.Generator) -> Structure:
    """The room's structure (module docstring); no plane and no point when the scene is no room (fewer than two
    bounding planes at an angle)."""
    planes, info = bounding_planes(points, max_planes, min_extent, iterations, rng)
    info["planes"] = [[round(float(v), 4) for v in p] for p in planes]
    normals_ = np.array([p[:3] for p in planes]).reshape(-1, 3)
    cos = np.abs(normals_ @ normals_.T)
    room = len(planes) >= 2 and bool(np.any(cos <= np.cos(np.radians(STRUCT_MIN_ANGLE_DEG))))
    info["room"] = room
    n = len(points)
    reach, height = np.full(n, np.inf), np.full(n, np.nan)
    if not room:
        return Structure(np.zeros((0, 4)), np.zeros(n, dtype=bool), reach, height, info)
    for p in planes:
        r, h = _plane_band(points, normals, p, sigmas, min_band)
        better = r < reach
        reach[better], height[better] = r[better], h[better]
    mask = reach <= 1.0
    info["points"] = int(mask.sum())
    return Structure(np.array(planes), mask, reach, height, info)
