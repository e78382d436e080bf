"""`kinfu diff` of two volumes whose world frames have different ups says so.

Before: the synthetic room fused from its z-up and its y-down recordings and diffed gave "2 removed and 4 added
regions" of up to 0.44 m^3 with only a low-overlap warning: nothing said that one world is the other turned 90 deg.
"""

import numpy as np

from kinfu_cli.change.diff import diff_grids
from kinfu_cli.core.grid import EMPTY, OCCUPIED, TernaryGrid


def _grid(up) -> TernaryGrid:
    lab = np.full((20, 20, 20), EMPTY, np.int8)
    lab[:, :, 5] = OCCUPIED
    return TernaryGrid(lab, np.zeros(3), 0.02, frame="world", up=np.asarray(up, dtype=float))


def test_ups_ninety_degrees_apart_are_a_warning():
    res = diff_grids(_grid((0, 0, 1)), _grid((0, -1, 0)))
    assert [w for w in res.warnings if "up directions differ by 90 deg" in w]


def test_ups_a_few_degrees_apart_are_one_frame():
    tilted = (0.0, np.sin(np.radians(5)), np.cos(np.radians(5)))
    res = diff_grids(_grid((0, 0, 1)), _grid(tilted))
    assert not [w for w in res.warnings if "up directions" in w] and len(res.regions) == 0
