"""The plot of `kinfu eval nbv`: unknown voxels against views taken, one line per strategy (the paper's Fig. 20)."""

from __future__ import annotations

import os

from kinfu_cli.report.figures import save_figure


def plot_nbv_loop(path: str | os.PathLike, doc: dict) -> None:
    """PNG of a `run_loop` document, written atomically: unknown voxels in each POI sphere vs views, one panel
    per POI; for the POI-free exploration, unknown voxels near the objects vs views in one panel."""
    import matplotlib  # heavy: loaded only when a plot is asked for

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if doc.get("kind") == "exploration":
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        for name, r in doc["strategies"].items():
            ax.plot(range(len(r["unknown_near"])), r["unknown_near"], marker="o",
                    label=f"{name} ({r['candidates_cast_total']} cast)")
        ax.set_xlabel("views")
        ax.set_ylabel("unknown voxels near objects")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, path, dpi=90)
        return
    pois = [str(p["id"]) for p in doc["pois"]]
    fig, axes = plt.subplots(1, len(pois), figsize=(5 * len(pois), 3.8), squeeze=False)
    for ax, pid in zip(axes[0], pois):
        for name, r in doc["strategies"].items():
            v = r["unknown"].get(pid, [])
            ax.plot(range(len(v)), v, marker="o", label=name)
        ax.set_xlabel("views")
        ax.set_ylabel("unknown voxels in S(POI)")
        ax.set_title(f"POI {pid}")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)
