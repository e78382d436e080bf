"""PNG slices of a ternary volume (the plots of `kinfu fuse`): occupied / empty / unknown per voxel."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.fusion.up import view_axes
from kinfu_cli.report.figures import save_figure

COLORS = {1: (0.80, 0.15, 0.10), 0: (0.55, 0.55, 0.55), -1: (1.0, 1.0, 1.0)}


def _rgb(labels2d: np.ndarray) -> np.ndarray:
    img = np.zeros(labels2d.shape + (3,))
    for k, c in COLORS.items():
        img[labels2d == k] = c
    return img


def _slice_axes(axis: int, up) -> tuple[int, int, bool, str]:
    """Plot axes (horizontal, vertical) of a slice across grid `axis`, whether the vertical one runs downwards
    (the world's up along a negative axis), and the view's name: slices across up are top views (right-handed
    seen from above, fusion.up.view_axes), the others side views with up pointing up. Without a snapped up
    (None, or tilted), the grid's own order, as before."""
    va = view_axes(up) if up is not None else None
    a, b = (i for i in range(3) if i != axis)
    if va is None or va.axis is None:
        return a, b, False, "slice"
    if axis == va.axis:
        return va.e1_axis, va.e2_axis, False, "top view"
    return (a if b == va.axis else b), va.axis, va.sign < 0, "side view"


def plot_slices(grid: TernaryGrid, outdir: str | os.PathLike, n: int = 4) -> list[Path]:
    """Write slices_xy.png, slices_xz.png, slices_yz.png: `n` evenly spaced slices through the observed
    part of the grid along each axis (red occupied, white empty, grey unknown). Slices across the volume's up
    (`grid.up`) are top views; the others show up pointing up, also for a y-down world. Returns the paths."""
    import matplotlib  # heavy: only when plotting

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lab = grid.labels
    up = getattr(grid, "up", None)
    observed = lab != 0
    out = []
    names = {2: "xy", 1: "xz", 0: "yz"}
    for axis, name in names.items():
        h, v, down, kind = _slice_axes(axis, up)
        other = tuple(i for i in range(3) if i != axis)
        occ_along = np.flatnonzero(observed.any(axis=other))
        if len(occ_along) == 0:
            occ_along = np.arange(lab.shape[axis])
        picks = np.unique(np.linspace(occ_along[0], occ_along[-1], n + 2)[1:-1].round().astype(int))
        fig, axs = plt.subplots(1, len(picks), figsize=(4 * len(picks), 4), squeeze=False)
        for ax, k in zip(axs[0], picks):
            sl = np.take(lab, k, axis=axis)  # remaining axes in grid order
            if (h, v) != other:
                sl = sl.T  # rows along h, columns along v
            lo = grid.origin
            vs = grid.voxel_size
            ext = [lo[h], lo[h] + sl.shape[0] * vs, lo[v], lo[v] + sl.shape[1] * vs]
            ax.imshow(np.transpose(_rgb(sl), (1, 0, 2)), origin="lower", extent=ext, interpolation="nearest")
            if down:
                ax.invert_yaxis()  # up is along -v: v grows downwards on the page
            coord = lo[axis] + (k + 0.5) * vs
            ax.set_title(f"{kind}: {'xyz'[axis]} = {coord:.3f} m")
            ax.set_xlabel(f"{'xyz'[h]} [m]")
            ax.set_ylabel(f"{'xyz'[v]} [m]" + (" (up is -" + "xyz"[v] + ")" if down else ""))
        fig.suptitle("ternary volume: red occupied, white empty, grey unknown")
        fig.tight_layout()
        path = Path(outdir) / f"slices_{name}.png"
        save_figure(fig, path, dpi=80)
        out.append(path)
    return out
