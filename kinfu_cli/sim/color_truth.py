"""Ground-truth surface colour of a generated scene, and the colour error of fused voxels at object borders.

The simulated camera's colour of a surface point (without pixel noise, auto-gain or misregistration) is the
albedo times the shading of sensor._shade_kernel, which does not depend on the viewpoint except for which
side of a surface faces the camera. `surface_truth` gives it for any points (the nearest surface point's),
with that point's label and distance. `border_color_errors` scores a fused colour volume against it: the
issue 12 measurement of the colour mode filter (edges stay sharp where the running mean blurs them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.ndimage import maximum_filter, minimum_filter

from kinfu_cli.sim.scene import RaycastTarget, Scene
from kinfu_cli.sim.sensor import BACKGROUND_RGB, LIGHT_DIR, _shade_kernel


def surface_truth(scene: Scene | RaycastTarget, points: np.ndarray, viewpoint) -> tuple[np.ndarray, np.ndarray,
                                                                                         np.ndarray]:
    """(colour float (n, 3) in 0..255, label int (n,), distance (n,) m) of the surface point nearest to each
    of the points (n, 3). viewpoint: a world point on the observed side of the surfaces (the cameras' mean
    position), which picks the side whose shading the camera saw."""
    target = scene if isinstance(scene, RaycastTarget) else scene.raycasting_scene()
    pts = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    ans = target.scene.compute_closest_points(o3d.core.Tensor.from_numpy(pts))
    near = ans["points"].numpy().astype(np.float64)
    gid = ans["geometry_ids"].numpy().astype(np.int64)
    normals = ans["primitive_normals"].numpy().astype(np.float32)
    vp = np.ascontiguousarray(viewpoint, dtype=np.float64).reshape(3)
    n = len(pts)
    rgb = _shade_kernel(np.ones((n, 1), bool), gid.reshape(n, 1), np.ones((n, 1)), (near - vp).reshape(n, 1, 3),
                        normals.reshape(n, 1, 3), vp, target.albedo.astype(np.float32),
                        target.textured.astype(np.int32), LIGHT_DIR.astype(np.float32),
                        BACKGROUND_RGB.astype(np.float32))
    colour = np.clip(rgb.reshape(n, 3) * 255.0, 0, 255)
    return colour, target.labels[gid], np.linalg.norm(near - pts, axis=1)


@dataclass
class BorderColorErrors:
    """RGB error (0..255, Euclidean) of fused voxel colours against the truth: at object borders (voxels within
    `radius` voxels of a voxel of another label) and elsewhere; per-voxel arrays and their summaries.

    A voxel in a concave corner (a box standing on the table) is seen as both surfaces, so its error against
    the nearest surface alone is bimodal for a filter that picks one colour. `border_blur` measures what a
    blurred edge is: the distance of each border voxel's colour to the nearest true colour within `radius`
    voxels (a sharp edge placed up to `radius` voxels off scores 0, a blend of the two sides does not)."""

    border: np.ndarray
    elsewhere: np.ndarray
    border_blur: np.ndarray
    radius: int

    def summary(self) -> dict:
        def stats(e):
            return {"voxels": int(e.size), "mean": float(e.mean()) if e.size else None,
                    "median": float(np.median(e)) if e.size else None,
                    "p90": float(np.percentile(e, 90)) if e.size else None}
        return {"border": stats(self.border), "elsewhere": stats(self.elsewhere),
                "border_blur": stats(self.border_blur), "radius_voxels": self.radius}


def border_color_errors(colors: np.ndarray, weights: np.ndarray, origin, voxel_size: float, scene, viewpoint,
                        radius: int = 2, max_distance_voxels: float = 1.0) -> BorderColorErrors:
    """Score dense fused colours (uint8 (X, Y, Z, 3), 0 0 0 = never coloured) and weights (X, Y, Z) of a box
    whose voxel (0, 0, 0) has its minimum corner at `origin`: the voxels with a colour and a weight whose
    centre lies within max_distance_voxels of the true surface are compared with surface_truth."""
    col = np.asarray(colors)
    mask = (np.asarray(weights) > 0) & (col.max(axis=-1) > 0)
    idx = np.argwhere(mask)
    centres = np.asarray(origin, dtype=np.float64) + (idx + 0.5) * voxel_size
    truth, labels, dist = surface_truth(scene, centres, viewpoint)
    near = dist <= max_distance_voxels * voxel_size
    idx, truth, labels = idx[near], truth[near], labels[near]
    err = np.linalg.norm(col[tuple(idx.T)].astype(np.float64) - truth, axis=1)
    lab = np.full(mask.shape, -1, dtype=np.int32)
    lab[tuple(idx.T)] = labels
    size = 2 * radius + 1
    hi = maximum_filter(lab, size=size, mode="constant", cval=-1)
    lo = minimum_filter(np.where(lab >= 0, lab, np.iinfo(np.int32).max), size=size, mode="constant",
                        cval=np.iinfo(np.int32).max)
    border = (hi[tuple(idx.T)] != labels) | (lo[tuple(idx.T)] != labels)
    return BorderColorErrors(err[border], err[~border], _blur(col, idx[border], truth, idx, mask.shape, radius),
                             radius)


def _blur(col: np.ndarray, at: np.ndarray, truth: np.ndarray, idx: np.ndarray, shape, radius: int) -> np.ndarray:
    """Per voxel of `at`: the smallest RGB distance between its colour and the truth of any scored voxel
    (idx, truth) within the (2 radius + 1)^3 cube around it; one vectorised pass per offset."""
    dense = np.full(tuple(shape) + (3,), np.nan, dtype=np.float32)
    dense[tuple(idx.T)] = truth
    c = col[tuple(at.T)].astype(np.float32)
    best = np.full(len(at), np.inf, dtype=np.float32)
    r = range(-radius, radius + 1)
    for off in np.array(np.meshgrid(r, r, r, indexing="ij")).reshape(3, -1).T:
        q = at + off
        ok = np.all((q >= 0) & (q < np.asarray(shape)), axis=1)
        t = np.full((len(at), 3), np.nan, dtype=np.float32)
        t[ok] = dense[tuple(q[ok].T)]
        d = np.linalg.norm(c - t, axis=1)
        best = np.fmin(best, d)
    return best.astype(np.float64)
