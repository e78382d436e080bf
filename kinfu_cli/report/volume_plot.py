"""PNG slices of a ternary volume (the plots of `kinfu fuse`): occupied / empty / unknown per voxel."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.report.figures import save_figure

COLORS = {1: (0.80, 0.15, 0.10), 0: (0.55, 0.55, 0.55), -1: (1.0, 1.0, 1.0)}


def _rgb(labels2d: np.ndarray) -> np.ndarray:
    img = np.zeros(labels2d.shape + (3,))
    for k, c in COLORS.items():
        img[labels2d == k] = c
    return img


def plot_slices(grid: TernaryGrid, outdir: str | os.PathLike, n: int = 4) -> list[Path]:
    """Write slices_xy.png, slices_xz.png, slices_yz.png: `n` evenly spaced slices through the observed
    part of the grid along each axis (red occupied, white empty, grey unknown). Returns the paths."""
    import matplotlib  # heavy: only when plotting

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lab = grid.labels
    observed = lab != 0
    out = []
    names = {2: ("xy", (0, 1)), 1: ("xz", (0, 2)), 0: ("yz", (1, 2))}
    for axis, (name, (a, b)) in names.items():
        other = tuple(i for i in range(3) if i != axis)
        occ_along = np.flatnonzero(observed.any(axis=other))
        if len(occ_along) == 0:
            occ_along = np.arange(lab.shape[axis])
        picks = np.unique(np.linspace(occ_along[0], occ_along[-1], n + 2)[1:-1].round().astype(int))
        fig, axs = plt.subplots(1, len(picks), figsize=(4 * len(picks), 4), squeeze=False)
        for ax, k in zip(axs[0], picks):
            sl = np.take(lab, k, axis=axis)  # remaining axes (a, b)
            lo = grid.origin
            vs = grid.voxel_size
            ext = [lo[a], lo[a] + sl.shape[0] * vs, lo[b], lo[b] + sl.shape[1] * vs]
            ax.imshow(np.transpose(_rgb(sl), (1, 0, 2)), origin="lower", extent=ext, interpolation="nearest")
            coord = lo[axis] + (k + 0.5) * vs
            ax.set_title(f"{'xyz'[axis]} = {coord:.3f} m")
            ax.set_xlabel(f"{'xyz'[a]} [m]")
            ax.set_ylabel(f"{'xyz'[b]} [m]")
        fig.suptitle("ternary volume: red occupied, white empty, grey unknown")
        fig.tight_layout()
        path = Path(outdir) / f"slices_{name}.png"
        save_figure(fig, path, dpi=80)
        out.append(path)
    return out
