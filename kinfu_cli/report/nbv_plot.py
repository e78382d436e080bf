"""PNG of a POI view ranking: volume slices through each POI with S(POI) and the top views as arrows."""

from __future__ import annotations

import os

import numpy as np

from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.fusion.up import view_axes
from kinfu_cli.nbv.ranking import PoiRanking
from kinfu_cli.report.figures import save_figure

_COLORS = {1: (0.15, 0.15, 0.15), 0: (0.65, 0.65, 0.75), -1: (1.0, 1.0, 1.0)}


def _slice_rgb(labels2d: np.ndarray) -> np.ndarray:
    rgb = np.empty(labels2d.shape + (3,))
    for v, c in _COLORS.items():
        rgb[labels2d == v] = c
    return rgb


def plot_nbv(path: str | os.PathLike, grid: TernaryGrid, rankings: list[PoiRanking], top: int = 5,
             span: float = 1.0, up=None) -> None:
    """One row per POI: top view (slice across `up` at the POI height; x-y for z up) and side view (slice
    along up through the POI, up pointing up; x-z for z up). The slices are the grid's own: up is taken
    as the world axis nearest to it. Dark = occupied, grey-blue = unknown, white = empty; circle = S(POI);
    arrows = the `top` best views (sensor position -> viewing direction), the best in red. Written
    atomically."""
    import matplotlib  # heavy; only needed to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    if up is not None:  # the world axis nearest to up, with its sign
        k = int(np.argmax(np.abs(up)))
        up = np.eye(3)[k] * np.sign(up[k])
    va = view_axes(up)
    a_up, h1, h2 = va.axis, va.e1_axis, va.e2_axis
    up_note = "" if va.sign > 0 and a_up == 2 else f" (up = {va.names[2]})"
    n = max(len(rankings), 1)
    fig, axes = plt.subplots(n, 2, figsize=(10, 4.8 * n), squeeze=False)
    vs, o = grid.voxel_size, grid.origin
    hi = o + np.array(grid.shape) * vs
    for row, r in zip(axes, rankings):
        c = r.center
        idx = np.clip(np.floor((c - o) / vs).astype(int), 0, np.array(grid.shape) - 1)
        order = r.scores.order()[:top]
        views = ((h1, h2, a_up, f"top view: {'xyz'[h1]}-{'xyz'[h2]} at POI height{up_note}"),
                 (h1, a_up, h2, f"side view: {'xyz'[h1]}-{'xyz'[a_up]} through POI{up_note}"))
        for ax, (a0, a1, fixed, name) in zip(row, views):
            sl = np.take(grid.labels, idx[fixed], axis=fixed)  # 2-D with the other two axes in order
            if a0 > a1:
                sl = sl.T  # axes (a0, a1)
            ax.imshow(_slice_rgb(sl).transpose(1, 0, 2), origin="lower", interpolation="nearest",
                      extent=(o[a0], hi[a0], o[a1], hi[a1]))
            ax.add_patch(Circle((c[a0], c[a1]), r.radius, fill=False, color="tab:orange", lw=1.5))
            for k, i in enumerate(order[::-1]):
                T = r.scores.poses[i]
                p, d = T[:3, 3], T[:3, 2] * 0.25
                best = i == order[0]
                ax.annotate("", xy=(p[a0] + d[a0], p[a1] + d[a1]), xytext=(p[a0], p[a1]),
                            arrowprops=dict(arrowstyle="->", color="red" if best else "tab:blue",
                                            lw=2.0 if best else 1.0))
            lim = span + 0.1
            ax.set_xlim(c[a0] - lim, c[a0] + lim)
            flip = a1 == a_up and va.sign < 0  # up along a negative axis: that axis runs downwards
            ax.set_ylim(*((c[a1] + lim, c[a1] - lim) if flip else (c[a1] - lim, c[a1] + lim)))
            ax.set_xlabel("xyz"[a0] + " (m)")
            ax.set_ylabel("xyz"[a1] + " (m)")
            state = "reconstructed" if r.reconstructed else f"best gain {r.best_gain:.0f}"
            ax.set_title(f"POI {r.poi_id}: {name}\n{state}, top {len(order)} views", fontsize=9)
            ax.set_aspect("equal")
    fig.tight_layout()
    save_figure(fig, path, dpi=90)
