"""`kinfu fuse --plot` slices follow the volume's up: side views show the floor at the bottom of the page, also
for a y-down world (cameras' optical frames, 7-Scenes), and slices across up are titled top views."""

import numpy as np
import pytest

from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.report.volume_plot import _slice_axes, plot_slices


def _floor_grid(up) -> TernaryGrid:
    """Empty 24^3 grid with an occupied floor slab 3 voxels thick at the low end of `up`."""
    lab = np.full((24, 24, 24), -1, np.int8)
    k = int(np.argmax(np.abs(up)))
    floor = [slice(None)] * 3
    floor[k] = slice(0, 3) if up[k] > 0 else slice(21, 24)
    lab[tuple(floor)] = 1
    return TernaryGrid(lab, origin=np.zeros(3), voxel_size=0.01, up=np.asarray(up, float))


def _red_rows(path) -> np.ndarray:
    import matplotlib.image as mpimg

    img = mpimg.imread(path)[..., :3]
    red = (img[..., 0] > 0.7) & (img[..., 1] < 0.3) & (img[..., 2] < 0.3)
    return np.flatnonzero(red.any(axis=1)) / img.shape[0]


@pytest.mark.parametrize("up, side", [((0, 0, 1), "slices_xz.png"), ((0, -1, 0), "slices_xy.png")])
def test_side_views_put_the_floor_at_the_bottom(tmp_path, up, side):
    plot_slices(_floor_grid(up), tmp_path, n=1)
    rows = _red_rows(tmp_path / side)
    assert len(rows) and rows.min() > 0.5, "the floor must be drawn in the lower half of a side view"


def test_slice_axes_of_a_y_down_world():
    up = np.array([0.0, -1.0, 0.0])
    assert _slice_axes(1, up)[3] == "top view"
    h, v, down, kind = _slice_axes(2, up)
    assert (h, v, down, kind) == (0, 1, True, "side view")
    h, v, down, kind = _slice_axes(0, up)
    assert (h, v, down) == (2, 1, True)
    assert _slice_axes(2, None) == (0, 1, False, "slice")  # no up known: the grid's own order
