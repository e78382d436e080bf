"""PNG of `kinfu grasp`: each object's superquadric(s), the support plane, and the chosen hand's ellipsoid H
with its frame (z approach in blue) and pre-grasp point, in a 3-D view and a top view."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.grasp.plan import GraspResult
from kinfu_cli.report.figures import save_figure
from kinfu_cli.segmentation.superquadric import Superquadric


def _ellipsoid(center: np.ndarray, R: np.ndarray, size, n: int = 14) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, np.pi, n // 2 + 1))
    local = np.stack([np.cos(u) * np.sin(v) * size[0], np.sin(u) * np.sin(v) * size[1], np.cos(v) * size[2]], -1)
    w = local @ R.T + center
    return w[..., 0], w[..., 1], w[..., 2]


def _sq_points(sq: Superquadric, n: int = 600) -> np.ndarray:
    return sq.sample_surface(n, rng=0)[0]


def plot_grasps(result: GraspResult, path: str | os.PathLike, dpi: int = 110) -> Path:
    """Write the figure atomically to `path` and return it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 6))
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    top = fig.add_subplot(1, 2, 2)
    allpts = []
    cmap = plt.get_cmap("tab10")
    for i, o in enumerate(result.objects):
        for k, sq in enumerate(o.parts):
            pts = _sq_points(sq)
            allpts.append(pts)
            c = cmap(i % 10)
            ax3.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=1, color=c, alpha=0.5)
            top.scatter(pts[:, 0], pts[:, 1], s=1, color=c, alpha=0.4)
        top.annotate(f"#{o.segment}", o.parts[0].center[:2], fontsize=8)
        g = o.best
        if g is None:
            continue
        R, p = g.rotation, g.position
        hc = p + R @ g.hand.h_center()
        ax3.plot_wireframe(*_ellipsoid(hc, R, g.hand.size), color="k", linewidth=0.4, alpha=0.6)
        for j, col in enumerate(("r", "g", "b")):
            e = p + 0.06 * R[:, j]
            ax3.plot([p[0], e[0]], [p[1], e[1]], [p[2], e[2]], color=col, linewidth=2)
        pre = p - o.pregrasp_distance * R[:, 2]
        ax3.scatter(*pre, color="m", s=15)
        top.plot([pre[0], p[0]], [pre[1], p[1]], color="m", linewidth=1.5)
        X, Y, _ = _ellipsoid(hc, R, g.hand.size)
        top.plot(X.ravel(), Y.ravel(), color="k", linewidth=0.2, alpha=0.4)
        top.annotate(o.best_hand or "", p[:2], fontsize=7, color="m")
    if allpts and result.plane is not None:
        pts = np.vstack(allpts)
        lo, hi = pts.min(axis=0) - 0.1, pts.max(axis=0) + 0.1
        n, d = result.plane[:3], result.plane[3]
        if abs(n[2]) > 0.3:
            xx, yy = np.meshgrid(np.linspace(lo[0], hi[0], 2), np.linspace(lo[1], hi[1], 2))
            zz = -(n[0] * xx + n[1] * yy + d) / n[2]
            ax3.plot_surface(xx, yy, zz, color="grey", alpha=0.2)
    if allpts:
        pts = np.vstack(allpts)
        ax3.set_box_aspect(np.maximum(pts.max(axis=0) - pts.min(axis=0) + 0.2, 0.05))
    ax3.set_xlabel("x (m)")
    ax3.set_ylabel("y (m)")
    ax3.set_zlabel("z (m)")
    ax3.set_title("objects, support plane, hand H\n(x red, y green, z approach blue)")
    top.set_aspect("equal")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.set_title("top view (magenta: pre-grasp -> grasp)")
    fig.tight_layout()
    return save_figure(fig, path, dpi)
