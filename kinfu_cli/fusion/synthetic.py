"""Synthetic RGB-D frames of boxes on a table, rendered exactly with open3d's RaycastingScene.

For fusion tests and benchmarks that must not depend on recordings: ground-truth mesh, poses and
depth with no noise (optionally Gaussian noise).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SynthBox:
    center: tuple  # (x, y) on the table
    size: tuple  # (sx, sy, height)
    yaw: float = 0.0
    color: tuple = (200, 60, 40)


@dataclass
class SynthScene:
    """A table top (plane z = 0, `table` m square) with boxes standing on it."""

    boxes: list = field(default_factory=lambda: [
        SynthBox((0.0, 0.0), (0.20, 0.12, 0.15), 0.3, (200, 60, 40)),
        SynthBox((0.25, 0.15), (0.10, 0.10, 0.25), -0.5, (40, 160, 60)),
        SynthBox((-0.22, 0.18), (0.16, 0.08, 0.08), 0.9, (50, 80, 200)),
    ])
    table: float = 1.2
    table_color: tuple = (170, 170, 150)

    def meshes(self):
        import open3d as o3d

        out = []
        t = o3d.geometry.TriangleMesh.create_box(self.table, self.table, 0.02)
        t.translate((-self.table / 2, -self.table / 2, -0.02))
        out.append((t, self.table_color))
        for b in self.boxes:
            m = o3d.geometry.TriangleMesh.create_box(*b.size)
            m.translate((-b.size[0] / 2, -b.size[1] / 2, 0.0))
            R = m.get_rotation_matrix_from_xyz((0.0, 0.0, b.yaw))
            m.rotate(R, center=(0.0, 0.0, 0.0))
            m.translate((b.center[0], b.center[1], 0.0))
            out.append((m, b.color))
        return out

    def mesh(self):
        """All parts as one open3d TriangleMesh (the ground truth surface)."""
        import open3d as o3d

        total = o3d.geometry.TriangleMesh()
        for m, _ in self.meshes():
            total += m
        return total


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """4x4 camera-to-world pose (optical frame: z forward, x right, y down) looking from eye at target."""
    eye = np.asarray(eye, float)
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, (1.0, 0.0, 0.0))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def orbit_poses(n: int, radius: float = 0.9, height: float = 0.7, target=(0.0, 0.0, 0.05),
                start_deg: float = 0.0, span_deg: float = 360.0) -> list[np.ndarray]:
    """n poses on a horizontal circle around `target`, all looking at it."""
    out = []
    for a in np.deg2rad(start_deg + span_deg * np.arange(n) / max(n, 1)):
        out.append(look_at((radius * np.cos(a) + target[0], radius * np.sin(a) + target[1], height), target))
    return out


def default_K(width: int = 640, height: int = 480, f: float | None = None) -> np.ndarray:
    f = 525.0 * width / 640.0 if f is None else f
    return np.array([[f, 0, width / 2 - 0.5], [0, f, height / 2 - 0.5], [0, 0, 1.0]])


class Renderer:
    """Ray casts a SynthScene into depth (float32 m, 0 = no hit) and RGB images."""

    def __init__(self, scene: SynthScene | None = None):
        import open3d as o3d

        self.scene_def = scene or SynthScene()
        self.scene = o3d.t.geometry.RaycastingScene()
        self.colors = []
        for m, c in self.scene_def.meshes():
            self.scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(m))
            self.colors.append(c)
        self.colors = np.array(self.colors, dtype=np.uint8)

    def render(self, K: np.ndarray, T_world_camera: np.ndarray, width: int, height: int,
               noise_std: float = 0.0, rng: np.random.Generator | None = None):
        import open3d as o3d

        u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
        dirs_c = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
        dirs_w = dirs_c @ T_world_camera[:3, :3].T
        origin = np.broadcast_to(T_world_camera[:3, 3], dirs_w.shape)
        rays = np.concatenate([origin, dirs_w], axis=-1).astype(np.float32)
        ans = self.scene.cast_rays(o3d.core.Tensor(rays))
        t = ans["t_hit"].numpy()  # along dirs with z = 1 in the camera: t is the depth
        ids = ans["geometry_ids"].numpy()
        hit = np.isfinite(t)
        depth = np.where(hit, t, 0).astype(np.float32)
        if noise_std > 0:
            rng = rng or np.random.default_rng(0)
            depth = np.where(hit, depth + rng.normal(0, noise_std, depth.shape).astype(np.float32), 0)
        color = np.zeros((height, width, 3), dtype=np.uint8)
        color[hit] = self.colors[np.minimum(ids[hit], len(self.colors) - 1)]
        return depth.astype(np.float32), color

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distance of world points to the ground-truth surface."""
        import open3d as o3d

        return self.scene.compute_distance(o3d.core.Tensor(np.asarray(points, dtype=np.float32))).numpy()
