"""Never-coloured (black) surface points are missing colour, not black: the thinning averages colours over the
coloured points only and a point left without one borrows its nearest coloured neighbour's (within 3 cm)."""

import numpy as np

from kinfu_cli.segmentation.surface import FILL_DISTANCE, SurfaceCloud, downsample, fill_uncoloured


def test_downsample_averages_over_coloured_points_only():
    rng = np.random.default_rng(0)
    # 16 clusters 5 cm apart, 10 points each within 1 mm of the centre: 6 of one colour, 4 black
    centres = np.stack(np.meshgrid(np.arange(4), np.arange(4), [0], indexing="ij"), -1).reshape(-1, 3) * 0.05
    pts = centres[:, None, :] + rng.uniform(-0.001, 0.001, (16, 10, 3))
    colour = rng.uniform(0.2, 0.9, (16, 1, 3)).repeat(10, axis=1)
    colour[:, 6:] = 0.0
    cloud = SurfaceCloud(pts.reshape(-1, 3), np.tile([0.0, 0.0, 1.0], (160, 1)), colour.reshape(-1, 3))
    out = downsample(cloud, 0.01)
    assert 16 <= len(out) < 160
    # each thinned point carries its cluster's colour exactly (black would pull it to 0.6 of it)
    near = np.argmin(np.linalg.norm(out.points[:, None, :] - centres[None], axis=2), axis=1)
    assert np.abs(out.colors - colour[near, 0]).max() < 1e-6


def test_black_points_borrow_the_nearest_colour_within_reach():
    pts = np.array([[0, 0, 0], [0.01, 0, 0], [0.02, 0, 0], [0.5, 0, 0]], float)
    col = np.array([[0.1, 0.5, 0.9], [0, 0, 0], [0, 0, 0], [0, 0, 0]], float)
    out = fill_uncoloured(pts, col)
    assert np.allclose(out[1], col[0]) and np.allclose(out[2], col[0])  # 1 and 2 cm away: filled
    assert np.all(out[3] == 0) and FILL_DISTANCE < 0.5  # nothing coloured within reach: stays uncoloured
    assert np.all(col[1] == 0)  # the input is not modified
