"""PNG renders of a segmentation: top and side views coloured by segment and by saliency, with each
segment's id and saliency, and the fitted superquadrics' surfaces (their predicted back sides). "Top" and
"side" follow the up direction the segmentation used (fusion.up.view_axes): looking down along it, and
across it with up pointing up. Each figure has a colour bar (segment ids, or saliency 0..1); labels are
placed so that they do not overlap (`place_labels`). A cloud with colours also gets colors.png: the
surface colours the segmentation saw (mean or mode-filtered, whatever the volume holds)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.fusion.up import view_axes
from kinfu_cli.report.figures import save_figure
from kinfu_cli.segmentation.outputs import saliency_colors, segment_colors
from kinfu_cli.segmentation.pipeline import SegmentResult
from kinfu_cli.segmentation.superquadric import SuperquadricFit

# label offsets (points) tried in turn, nearest first, until a label overlaps none placed before it
_OFFSETS = [(dx, dy) for r in (4, 14, 26, 40, 56) for dx, dy in
            ((r, r), (r, -r - 8), (-r - 30, r), (-r - 30, -r - 8), (0, r + 6), (0, -r - 14))]


def place_labels(ax, items) -> list:
    """Annotate ax with items (x, y, text), each at the first offset where its box overlaps no earlier
    label; returns the labels' display boxes (a label that fits nowhere keeps the last offset tried)."""
    from matplotlib.text import Text

    renderer = ax.figure.canvas.get_renderer()
    boxes = []
    for x, y, text in items:
        for dx, dy in _OFFSETS:
            a = ax.annotate(text, (x, y), xytext=(dx, dy), textcoords="offset points", fontsize=7,
                            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7},
                            arrowprops={"arrowstyle": "-", "lw": 0.4, "color": "0.3"})
            a.update_positions(renderer)  # place the text at its offset (done at draw time otherwise)
            box = Text.get_window_extent(a, renderer)  # the text alone, not its leader line
            if not any(box.overlaps(b) for b in boxes):
                break
            if (dx, dy) != _OFFSETS[-1]:
                a.remove()
        boxes.append(box)
    return boxes


def _segment_colorbar(fig, axes, labels: np.ndarray, plt) -> None:
    """A discrete colour bar of the segment colours: support plane (0) and the segment ids."""
    from matplotlib.colors import BoundaryNorm, ListedColormap

    ids = np.unique(labels[labels >= 0])
    if len(ids) == 0:
        return
    cols = segment_colors(ids)
    cmap = ListedColormap(cols)
    norm = BoundaryNorm(np.arange(len(ids) + 1) - 0.5, len(ids))
    cb = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=axes, shrink=0.85, pad=0.02)
    step = max(1, int(np.ceil(len(ids) / 25)))
    cb.set_ticks(np.arange(len(ids))[::step])
    cb.set_ticklabels(["plane" if i == 0 else str(i) for i in ids[::step]])
    cb.set_label("segment")


def plot_segments(result: SegmentResult, outdir: str | os.PathLike) -> dict[str, Path]:
    """segments.png and saliency.png (and colors.png when the cloud has colours) in `outdir`, written
    atomically; returns name -> path."""
    import matplotlib  # heavy; only needed to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize

    out = Path(outdir)
    seg = result.segmentation
    up = result.options.segmentation.up_vector()
    if up is None and seg.plane is not None:  # any plane was allowed: the support plane's normal is up
        up = seg.plane[:3]
    axes = view_axes(up)
    basis = np.stack([axes.e1, axes.e2, axes.up])  # plot coordinates of world points: basis @ p
    pts = seg.points @ basis.T
    figures = [("segments.png", segment_colors(seg.labels)),
               ("saliency.png", saliency_colors(seg.labels, result.saliency))]
    if seg.colors is not None:
        figures.append(("colors.png", np.clip(seg.colors, 0, 1)))
    files = {}
    for name, col in figures:
        fig, panels = plt.subplots(1, 2, figsize=(14, 5.5), layout="constrained")
        views = ((0, 1, f"top view, looking down along up ({axes.names[0]}, {axes.names[1]})"),
                 (0, 2, f"side view ({axes.names[0]}, {axes.names[2]})"))
        for ax, (i, j, title) in zip(panels, views):
            order = np.argsort(pts[:, 3 - i - j]) if (i, j) == (0, 2) else np.argsort(pts[:, 2])
            ax.scatter(pts[order, i], pts[order, j], c=col[order], s=2, linewidths=0)
            if name == "segments.png":
                for s in result.saliency:
                    fit = result.superquadrics.get(s.id)
                    if isinstance(fit, SuperquadricFit):
                        sp = fit.superquadric.sample_surface(400, 0)[0] @ basis.T
                        ax.scatter(sp[:, i], sp[:, j], s=0.3, c="k", alpha=0.3, linewidths=0)
            # the scene's extent: a superquadric fitted to a wall may reach metres past it
            for lim, k in ((ax.set_xlim, i), (ax.set_ylim, j)):
                lo, hi = float(pts[:, k].min()), float(pts[:, k].max())
                pad = max(0.05 * (hi - lo), 0.02)
                lim(lo - pad, hi + pad)
            ax.set_aspect("equal")
            ax.set_title(title)
            ax.set_xlabel(axes.names[i] + " (m)")
            ax.set_ylabel(axes.names[j] + " (m)")
        if name == "segments.png":
            _segment_colorbar(fig, panels, seg.labels, plt)
        elif name == "saliency.png":
            cb = fig.colorbar(plt.cm.ScalarMappable(norm=Normalize(0, 1), cmap="viridis"), ax=panels, shrink=0.85,
                              pad=0.02)
            cb.set_label("saliency (support plane and noise: grey)")
        fig.suptitle({"segments.png": "segments (superquadrics in black)",
                      "saliency.png": "saliency = isolation x roundness",
                      "colors.png": "surface colour from the volume"}[name])
        fig.canvas.draw()  # final layout first, then frozen: labels are placed in display space
        fig.set_layout_engine("none")
        for ax, (i, j, _) in zip(panels, views):
            items = []
            for s in result.objects[:15]:  # background segments keep their colour, not a label
                c = basis @ s.centroid
                items.append((c[i], c[j], f"{s.id}: {s.saliency:.2f}"))
            place_labels(ax, items)
        save_figure(fig, out / name, dpi=110)
        files[name] = out / name
    return files
