"""PNGs of `kinfu eval segment`: the scored points seen from above (looking down the up direction) coloured
by their consistency error, with a colour bar and each true object's name; and the sweep's
precision/recall curves, one per scene. Labels are pushed apart so that none overlaps another."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.fusion.up import view_axes
from kinfu_cli.report.figures import save_figure


def spread_labels(anchors: np.ndarray, box: tuple[float, float], bounds: tuple[float, float] | None = None
                  ) -> np.ndarray:
    """Positions for text boxes of size `box` (w, h, data units) near `anchors` (n, 2) so that no two boxes
    overlap: each label, in order of its anchor's height, is moved up by whole box heights (down when
    `bounds` (ymin, ymax) would be passed) until it is clear of those already placed."""
    anchors = np.asarray(anchors, dtype=float).reshape(-1, 2)
    w, h = box
    placed: list[np.ndarray] = []
    out = np.zeros_like(anchors)
    for i in np.argsort(anchors[:, 1], kind="stable"):  # a few dozen labels at most: a loop over labels
        for step in range(0, 4 * len(anchors) + 1):
            k = (step + 1) // 2 * (1 if step % 2 else -1) if bounds is not None else step
            pos = anchors[i] + np.array([0.0, k * h])
            if bounds is not None and not bounds[0] <= pos[1] <= bounds[1] - h:
                continue
            if all(abs(pos[0] - q[0]) >= w or abs(pos[1] - q[1]) >= h for q in placed):
                break
        placed.append(pos)
        out[i] = pos
    return out


def plot_segment_errors(points: np.ndarray, errors: np.ndarray, gt_labels: np.ndarray, names: dict[int, str],
                        up, path: str | os.PathLike, title: str = "") -> Path:
    """Top view of the scored points coloured by max(E(S,G,p), E(G,S,p)) (0..1, colour bar), each true
    object's name at its points' centre."""
    import matplotlib  # heavy; only needed to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes = view_axes(up)
    basis = np.stack([axes.e1, axes.e2, axes.up])
    pts = np.asarray(points, dtype=float) @ basis.T
    order = np.argsort(pts[:, 2])  # higher points drawn last: what one sees from above
    fig, ax = plt.subplots(figsize=(9, 7))
    sc = ax.scatter(pts[order, 0], pts[order, 1], c=np.asarray(errors)[order], cmap="inferno_r", vmin=0, vmax=1,
                    s=3, linewidths=0)
    fig.colorbar(sc, ax=ax, label="consistency error max(E(S,G,p), E(G,S,p))")
    ids = [int(v) for v in np.unique(gt_labels) if v > 0]
    if ids and len(pts):  # zoom on the true objects (the floor and walls would shrink them to dots)
        obj = pts[np.isin(gt_labels, ids), :2]
        lo, hi = obj.min(axis=0) - 0.15, obj.max(axis=0) + 0.15
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        anchors = np.array([pts[gt_labels == i, :2].mean(axis=0) for i in ids])
        span = float(np.max(hi - lo))
        text = [names.get(i, str(i)) for i in ids]
        wbox = span * 0.013 * max(len(t) for t in text)
        pos = spread_labels(anchors + [0.0, 0.02 * span], (wbox, span * 0.04), bounds=(lo[1], hi[1]))
        for t, a, p in zip(text, anchors, pos):
            ax.annotate(t, a, xytext=p, fontsize=8, ha="center", va="bottom",
                        bbox={"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.8, "lw": 0},
                        arrowprops={"arrowstyle": "-", "lw": 0.5})
    ax.set_aspect("equal")
    ax.set_xlabel(f"{axes.names[0]} (m)")
    ax.set_ylabel(f"{axes.names[1]} (m)")
    ax.set_title(title or f"top view (looking down {axes.names[2]}): per-point segmentation error")
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_sweep_pr(doc: dict, path: str | os.PathLike) -> Path:
    """Boundary precision/recall curves of the sweep document: thin, one per scene volume (colour = scene,
    line style = colour mode), each point a threshold value; thick, the mean per colour mode (as thesis Figs.
    4.10-4.11: "not enhanced" mean colour against the mode filter), its best-F value labelled."""
    import matplotlib  # heavy; only needed to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 6))
    cmap = plt.get_cmap("tab10")
    styles = {"mode": "-", "mean": "--", "none": ":"}
    mean_colours = {"mode": "black", "mean": "tab:red", "none": "tab:gray"}
    scene_ids = list(dict.fromkeys((s.get("layout", "objects"), s["seed"]) for s in doc["scenes"]))
    pts = []
    for s in doc["scenes"]:
        k = scene_ids.index((s.get("layout", "objects"), s["seed"]))
        r = np.array([[row["boundary_recall"], row["boundary_precision"]] for row in s["rows"]])
        pts.append(r)
        c = s.get("color", "none")
        ax.plot(r[:, 0], r[:, 1], styles.get(c, "-"), marker="o", ms=2.5, lw=0.8, alpha=0.45, color=cmap(k % 10),
                label=f"{s.get('layout', 'objects')} {s['seed']}" if c == doc["scenes"][0].get("color", "none")
                else None)
    best = []
    for c, m in doc.get("means", {}).items():
        r = np.stack([m["boundary_recall"], m["boundary_precision"]], axis=1)
        pts.append(r)
        ax.plot(r[:, 0], r[:, 1], styles.get(c, "-"), marker="s", ms=5, lw=2.2, color=mean_colours.get(c, "k"),
                label=f"mean, {c} colour" if c != "none" else "mean, no colour")
        i = int(np.argmax(m["boundary_f"]))
        best.append((r[i], f"{c}: {doc['parameter']} {doc['values'][i]:g}", mean_colours.get(c, "k")))
    allp = np.concatenate(pts) if pts else np.ones((1, 2))
    lo = min(0.5, float(allp.min()) - 0.05)
    ax.set_xlim(lo, 1.01)
    ax.set_ylim(lo, 1.01)
    if best:
        pos = spread_labels(np.array([b[0] for b in best]) + [0.0, 0.02], (0.25, 0.03), bounds=(lo, 1.01))
        for (a, t, c), p in zip(best, pos):
            ax.annotate(t, a, xytext=p, fontsize=8, color=c, ha="center",
                        arrowprops={"arrowstyle": "-", "lw": 0.5, "color": c})
    ax.set_xlabel(f"boundary recall (T_eval = {doc['t_eval'] * 100:.0f} cm)")
    ax.set_ylabel("boundary precision")
    ax.set_title(f"segmentation PR over {doc['parameter']} ({doc.get('method', 'lccp')})")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
