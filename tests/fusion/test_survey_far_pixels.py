"""The auto grid's survey keeps the farthest pixel of every 8 x 8 tile, not only the tile's corner pixel.

Before: the second half of the 7-Scenes kitchen (`kinfu import`, then `kinfu fuse --start 1.0`) reached 9.5 cm
beyond the surveyed points at its far side (observed max z 3.42 m, occupied up to the grid face at 3.52 m): a
285-voxel patch was cut by the auto grid, "occupied voxels touch the grid faces z+ (15)". With the farthest
pixels the survey reaches 3.59 m and no face is touched.
"""

import numpy as np

from kinfu_cli.fusion.extent import SURVEY_STRIDE, survey

K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])


def test_a_far_pixel_between_the_sampled_ones_bounds_the_survey():
    depth = np.full((48, 64), 1.0)
    depth[13, 21] = 3.0  # off the stride-8 lattice: the sparse sample alone never sees it
    assert depth[::SURVEY_STRIDE, ::SURVEY_STRIDE].max() == 1.0
    seen = survey([(depth, K, np.eye(4))], min_depth=0.3, max_depth=4.0)
    assert seen.points[:, 2].max() == 3.0
    far = seen.points[np.argmax(seen.points[:, 2])]
    assert np.allclose(far, [(21 - 31.5) / 100 * 3.0, (13 - 23.5) / 100 * 3.0, 3.0])


def test_pixels_out_of_range_stay_out():
    depth = np.full((48, 64), 1.0)
    depth[13, 21] = 5.0  # beyond max_depth
    depth[30, 30] = np.nan
    seen = survey([(depth, K, np.eye(4))], min_depth=0.3, max_depth=4.0)
    assert seen.points[:, 2].max() == 1.0 and np.all(np.isfinite(seen.points))
