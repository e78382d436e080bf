"""PNG renders of a segmentation: top and side views coloured by segment and by saliency, with each
segment's id and saliency, and the fitted superquadrics' surfaces (their predicted back sides). "Top" and
"side" follow the up direction the segmentation used (fusion.up.view_axes): looking down along it, and
across it with up pointing up."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.fusion.up import view_axes
from kinfu_cli.report.figures import save_figure
from kinfu_cli.segmentation.outputs import saliency_colors, segment_colors
from kinfu_cli.segmentation.pipeline import SegmentResult
from kinfu_cli.segmentation.superquadric import SuperquadricFit


def plot_segments(result: SegmentResult, outdir: str | os.PathLike) -> dict[str, Path]:
    """segments.png and saliency.png in `outdir`, written atomically; returns name -> path."""
    import matplotlib  # heavy; only needed to plot

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(outdir)
    seg = result.segmentation
    up = result.options.segmentation.up_vector()
    if up is None and seg.plane is not None:  # any plane was allowed: the support plane's normal is up
        up = seg.plane[:3]
    axes = view_axes(up)
    basis = np.stack([axes.e1, axes.e2, axes.up])  # plot coordinates of world points: basis @ p
    pts = seg.points @ basis.T
    files = {}
    for name, col in (("segments.png", segment_colors(seg.labels)),
                      ("saliency.png", saliency_colors(seg.labels, result.saliency))):
        fig, panels = plt.subplots(1, 2, figsize=(13, 5.5))
        views = ((0, 1, f"top view ({axes.names[0]}, {axes.names[1]})"),
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
            for s in result.saliency[:15]:
                c = basis @ s.centroid
                ax.annotate(f"{s.id}: {s.saliency:.2f}", (c[i], c[j]), fontsize=7)
            ax.set_aspect("equal")
            ax.set_title(title)
            ax.set_xlabel(axes.names[i] + " (m)")
            ax.set_ylabel(axes.names[j] + " (m)")
        fig.suptitle("segments (superquadrics in black)" if name == "segments.png"
                     else "saliency = isolation x roundness (viridis, 0..1)")
        fig.tight_layout()
        save_figure(fig, out / name, dpi=110)
        files[name] = out / name
    return files
