"""PNG of a hand trajectory with its POIs (like RAS 2016 Figs. 7-8), matplotlib Agg.

GMM-AS: 3-D trajectory with the 1-σ ellipsoids of the Gaussians coloured by saliency, POIs as stars
with their region radius; a bar chart of saliency vs threshold per Gaussian (Tables 5-6).
ZVC: 3-D trajectory with the slow samples highlighted and the POIs; v̄(r1)·ZVCTh and v̄(r2) over time.
"""

from __future__ import annotations

import os

import numpy as np

from kinfu_cli.io.trajectory import Trajectory
from kinfu_cli.report.figures import save_figure


def _ellipsoid(mean: np.ndarray, cov: np.ndarray, n: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    vals, vecs = np.linalg.eigh(cov)
    radii = np.sqrt(np.maximum(vals, 0.0))
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n), np.linspace(0, np.pi, n // 2))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    pts = sphere @ (vecs * radii).T + mean
    return pts[..., 0], pts[..., 1], pts[..., 2]


def _equal_axes(ax, pts: np.ndarray) -> None:
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    c, r = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 0.05)
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)


def plot_pois(path: str | os.PathLike, traj: Trajectory, detector, title: str = "") -> None:
    """Write the figure for a fitted GmmActivitySaliency or ZeroVelocityCrossing to `path` (atomic)."""
    import matplotlib  # heavy: loaded only when a plot is asked for

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors

    fig = plt.figure(figsize=(12, 5.5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    p = traj.positions
    pois = detector.pois_
    if getattr(detector, "algorithm", "") == "gmm-as":
        ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.3", lw=0.8)
        s = np.asarray(detector.saliency_)
        norm = colors.LogNorm(vmin=max(s.min(), 1e-12), vmax=max(s.max(), s.min() * 1.0001, 1e-12))
        cmap = matplotlib.colormaps["viridis"]
        for g, gauss in enumerate(detector.gaussians_):
            x, y, z = _ellipsoid(gauss.mean[:3], gauss.covariance[:3, :3])
            ax.plot_surface(x, y, z, color=cmap(norm(s[g])), alpha=0.35, linewidth=0)
            ax.text(*gauss.mean[:3], str(g + 1), fontsize=7)
        fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.6, label="saliency")
        idx = np.arange(1, len(s) + 1)
        poi_comp = {q.extra.get("component") for q in pois}
        ax2.bar(idx, s, color=["tab:red" if g in poi_comp else "tab:blue" for g in range(len(s))])
        th = np.asarray(detector.thresholds_)
        ax2.plot(idx, th, "k_", markersize=18, mew=2, label="threshold")
        ax2.set_yscale("log")
        ax2.set_xlabel("Gaussian (sorted by time)")
        ax2.set_ylabel("saliency")
        ax2.set_title(f"GMM-AS: K = {len(s)}, {len(pois)} POI(s) (red)")
        ax2.legend()
    else:
        slow = np.asarray(detector.slow_)
        q = detector.filtered_
        ax.plot(q[:, 0], q[:, 1], q[:, 2], color="0.3", lw=0.8)
        ax.scatter(q[slow, 0], q[slow, 1], q[slow, 2], s=4, color="tab:orange", label="slow")
        t = traj.t - traj.t[0]
        ax2.plot(t, detector.speed_r1_, label="v(r1)")
        ax2.plot(t, detector.slow_limit_, label=f"slow below ({detector.rule_} rule)")
        ax2.fill_between(t, 0, np.where(slow, detector.speed_r2_.max(), 0), color="tab:orange", alpha=0.2)
        ax2.set_xlabel("time (s)")
        ax2.set_ylabel("mean speed (m/s)")
        ax2.set_title(f"ZVC: {len(pois)} POI(s)")
        ax2.legend()
    for poi in pois:
        ax.scatter(*poi.position, marker="*", s=160, color="tab:red", depthshade=False)
        x, y, z = _ellipsoid(poi.position, np.eye(3) * poi.radius ** 2, n=12)
        ax.plot_wireframe(x, y, z, color="tab:red", linewidth=0.3, alpha=0.4)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    _equal_axes(ax, p)
    ax.set_title(title or (traj.source or "hand trajectory"), fontsize=9)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


def plot_task_pois(path: str | os.PathLike, traj: Trajectory, tasks, detectors, workspace=None,
                   title: str = "") -> None:
    """Figure for a stream cut into tasks (attention/tasks.py): the trajectory with each task in its own
    colour (samples outside every task in grey), the workspace box and the POIs (3-D, left); x, y, z
    over time with the task spans shaded and the POI times marked (right). Written atomically."""
    import matplotlib  # heavy: loaded only when a plot is asked for

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 5.5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    p = traj.positions
    t = traj.t
    cmap = matplotlib.colormaps["tab10"]
    ax.plot(p[:, 0], p[:, 1], p[:, 2], color="0.75", lw=0.5)
    for axis, c in zip(range(3), ("0.1", "0.4", "0.65")):  # greys: colours belong to the tasks
        ax2.plot(t, p[:, axis], color=c, lw=0.8, label="xyz"[axis])
    for task, det in zip(tasks, detectors):
        col = cmap(task.index % 10)
        q = task.trajectory.positions
        ax.plot(q[:, 0], q[:, 1], q[:, 2], color=col, lw=1.0)
        ax2.axvspan(task.t_start, task.t_end, color=col, alpha=0.15)
        ax2.text(task.t_start, 1.0, f"task {task.index}", transform=ax2.get_xaxis_transform(), fontsize=7,
                 va="bottom", color=col)
        for poi in det.pois_:
            ax.scatter(*poi.position, marker="*", s=160, color=col, edgecolors="k", depthshade=False)
            x, y, z = _ellipsoid(poi.position, np.eye(3) * poi.radius ** 2, n=12)
            ax.plot_wireframe(x, y, z, color=col, linewidth=0.3, alpha=0.4)
            ax2.axvline(poi.time, color=col, lw=1.2, ls="--")
    if workspace is not None:
        w = np.asarray(workspace, dtype=np.float64)
        corners = np.array([[w[3 if i & 1 else 0], w[4 if i & 2 else 1], w[5 if i & 4 else 2]]
                            for i in range(8)])
        for a in range(8):
            for b in (1, 2, 4):
                if not a & b:
                    ax.plot(*corners[[a, a | b]].T, color="k", lw=0.6, ls=":")
    n_pois = sum(len(d.pois_) for d in detectors)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    _equal_axes(ax, p)
    ax.set_title(title or (traj.source or "hand trajectory"), fontsize=9)
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("position (m)")
    ax2.set_title(f"{len(tasks)} task(s) (shaded), {n_pois} POI(s) (dashed)", pad=14)
    ax2.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
