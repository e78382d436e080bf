"""The colour distance of T_lccp / T_ff: lighting scales a face's colour (shading, camera gain). The thesis' RGB
distance then cuts one box into its faces; the chromaticity distance ("chroma") and the angle ignore the scale,
so the same block stays one object per hue."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.segmentation.color_distances import color_distance
from kinfu_cli.segmentation.segments import SegmentationParams, segment_cloud
from tests.segmentation.test_segment_color import block_scene

LIGHT = np.array([0.3, -0.4, 1.0]) / np.linalg.norm([0.3, -0.4, 1.0])  # as the simulator's light


def shaded_block_scene():
    """test_segment_color's flush red | blue block (and the table) shaded by ambient + Lambert from LIGHT: the top
    at 0.93 of its albedo, the sides from 0.35 to 0.57: a side differs from its top by up to 0.45 in RGB and not at
    all in chromaticity."""
    pts, nrm, col, truth = block_scene()
    shade = 0.35 + 0.65 * np.clip(nrm @ LIGHT, 0.0, 1.0)
    return pts, nrm, np.clip(col * shade[:, None], 0, 1), truth


def _halves(seg, truth):
    """For each coloured half: (share of its points in its largest segment, purity of that segment)."""
    out = []
    for half in (1, 2):
        lab = seg.labels[truth == half]
        ids, counts = np.unique(lab, return_counts=True)
        best = ids[np.argmax(counts)]
        out.append((counts.max() / len(lab), np.mean(truth[seg.labels == best] == half) if best > 0 else 0.0))
    return out


def test_distances_ignore_brightness_but_not_hue():
    rng = np.random.default_rng(3)
    c = rng.uniform(0.05, 1.0, (200, 3))
    scale = rng.uniform(0.3, 1.0, (200, 1))
    for kind in ("chroma", "angle"):
        assert np.max(color_distance(c, c * scale, kind)) < 1e-6  # arccos near 1: ~1e-8
    assert np.min(color_distance(c, c * 0.5, "rgb")) > 0.0  # the thesis' distance sees shading
    red, blue, black = np.array([[0.8, 0.1, 0.1]]), np.array([[0.1, 0.2, 0.8]]), np.zeros((1, 3))
    assert color_distance(red, blue, "chroma")[0] > 0.5 and color_distance(red, blue, "angle")[0] > 1.0
    assert np.isclose(color_distance(red, blue, "rgb")[0], np.linalg.norm(red - blue))
    grey = np.full((1, 3), 0.4)
    for kind in ("chroma", "angle"):  # black has no hue: grey, not an outlier
        assert color_distance(black, grey, kind)[0] < 1e-6
        assert np.all(color_distance(np.r_[red, blue], np.r_[blue, red], kind) <= (np.sqrt(2) if kind == "chroma"
                                                                                  else np.pi / 2) + 1e-12)


def test_shading_splits_faces_in_rgb_not_in_chromaticity():
    pts, nrm, col, truth = shaded_block_scene()
    base = dict(up=(0.0, 0.0, 1.0), method="lccp")
    rgb = segment_cloud(pts, nrm, SegmentationParams(**base, t_lccp=0.2, color_distance="rgb"), col)
    assert min(share for share, _ in _halves(rgb, truth)) < 0.8  # a half is cut into its faces
    chroma = segment_cloud(pts, nrm, SegmentationParams(**base, t_lccp=0.1, color_distance="chroma"), col)
    assert len([v for v in np.unique(chroma.labels) if v > 0]) == 2
    for share, purity in _halves(chroma, truth):  # one segment per hue, whatever the face's shade
        assert share >= 0.95 and purity >= 0.95


def test_flood_fill_with_chromaticity_keeps_shaded_faces_together():
    pts, nrm, col, truth = shaded_block_scene()
    p = SegmentationParams(up=(0.0, 0.0, 1.0), method="flood-fill", normal_importance=0.3, t_ff=0.35,
                           color_distance="chroma")
    for share, purity in _halves(segment_cloud(pts, nrm, p, col), truth):
        assert share >= 0.95 and purity >= 0.95


@pytest.mark.parametrize("value", ["lab", "RGB", ""])
def test_unknown_colour_distance_is_named(value):
    with pytest.raises(ConfigError) as e:
        SegmentationParams(color_distance=value).validate()
    assert e.value.parameter == "color_distance"
