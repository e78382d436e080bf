"""Colour in segmentation: a red and a blue box side by side form one flush block that shape alone cannot
split; colour-pruned LCCP (T_lccp) and Flood Fill (T_ff) split it at the colour edge."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_cloud
from kinfu_cli.segmentation.segments import SegmentationParams, segment_cloud

STEP = 0.005


def _face(u, v, origin, du, dv, normal):
    a, b = np.meshgrid(np.arange(0, u, STEP) + STEP / 2, np.arange(0, v, STEP) + STEP / 2, indexing="ij")
    p = np.asarray(origin) + a.reshape(-1, 1) * du + b.reshape(-1, 1) * dv
    return p, np.tile(normal, (len(p), 1))


def block_scene():
    """Table z = 0 (0.6 m square, wood-brown) and a 0.2 x 0.1 x 0.1 m block whose x < 0.1 half is red and
    other half blue; points every 5 mm with outward normals."""
    ex, ey, ez = np.eye(3)
    parts = [_face(0.6, 0.6, (-0.2, -0.25, 0), ex, ey, ez)]
    table = np.ones(len(parts[0][0]), bool)
    parts += [_face(0.2, 0.1, (0, 0, 0.1), ex, ey, ez), _face(0.2, 0.1, (0, 0, 0), ex, ez, -ey),
              _face(0.2, 0.1, (0, 0.1, 0), ex, ez, ey), _face(0.1, 0.1, (0, 0, 0), ey, ez, -ex),
              _face(0.1, 0.1, (0.2, 0, 0), ey, ez, ex)]
    pts = np.concatenate([p for p, _ in parts])
    nrm = np.concatenate([n for _, n in parts])
    on_table = np.r_[table, np.zeros(len(pts) - len(table), bool)]
    keep = ~(on_table & (pts[:, 0] > 0) & (pts[:, 0] < 0.2) & (pts[:, 1] > 0) & (pts[:, 1] < 0.1))  # under the block
    pts, nrm, on_table = pts[keep], nrm[keep], on_table[keep]
    rng = np.random.default_rng(0)
    col = np.where(on_table[:, None], [0.6, 0.45, 0.3], np.where(pts[:, :1] < 0.1, [0.8, 0.1, 0.1], [0.1, 0.2, 0.8]))
    col = np.clip(col + rng.normal(0, 0.02, col.shape), 0, 1)
    truth = np.where(on_table, 0, np.where(pts[:, 0] < 0.1, 1, 2))
    return pts, nrm, col, truth


def _objects(seg):
    return sorted(int(v) for v in np.unique(seg.labels) if v > 0)


@pytest.mark.parametrize("params", [dict(method="lccp", t_lccp=0.3), dict(method="flood-fill", normal_importance=0.3)])  # sharp faces: 1 - n1.n2 = 1
def test_colour_splits_the_flush_block(params):
    pts, nrm, col, truth = block_scene()
    p = SegmentationParams(up=(0.0, 0.0, 1.0), **params)
    with_colour = segment_cloud(pts, nrm, p, col)
    assert with_colour.plane is not None and with_colour.stats["colors"]
    assert len(_objects(with_colour)) == 2
    for half in (1, 2):  # each coloured half is one segment, >= 95 % of its points, holding nothing else
        lab = with_colour.labels[truth == half]
        ids, counts = np.unique(lab, return_counts=True)
        best = ids[np.argmax(counts)]
        assert best > 0 and counts.max() >= 0.95 * len(lab)
        assert np.mean(truth[with_colour.labels == best] == half) >= 0.95
    if params["method"] == "lccp":  # by shape alone the flush block is one convex object
        assert len(_objects(segment_cloud(pts, nrm, p))) == 1
        assert with_colour.stats["color_pruned_pairs"] > 0


def test_colour_term_off_without_colours_and_flood_fill_or_t_lccp_warns():
    pts, nrm, col, _ = block_scene()
    opts = SegmentOptions(superquadrics=False, segmentation=SegmentationParams(up=(0.0, 0.0, 1.0), method="flood-fill"))
    res = analyse_cloud(pts, nrm, opts)
    assert res.segmentation.colors is None and not res.segmentation.stats["colors"]
    assert len(res.warnings) == 1 and "flood fill without colour" in res.warnings[0]
    res = analyse_cloud(pts, nrm, opts, colors=col)
    assert res.warnings == [] and res.to_json()["stats"]["method"] == "flood-fill"
    lccp = SegmentOptions(superquadrics=False, segmentation=SegmentationParams(up=(0.0, 0.0, 1.0), t_lccp=0.1))
    res = analyse_cloud(pts, nrm, lccp)
    assert len(res.warnings) == 1 and "t_lccp 0.1 without colour" in res.warnings[0]
    assert res.segmentation.stats["color_pruned_pairs"] == 0
    assert analyse_cloud(pts, nrm, lccp, colors=col).warnings == []


@pytest.mark.parametrize("name,value", [("method", "watershed"), ("t_lccp", -0.1), ("t_ff", 0.0),
                                        ("color_importance", -1.0), ("plane_color_margin", -0.01)])
def test_bad_colour_parameters_are_named(name, value):
    with pytest.raises(ConfigError) as e:
        SegmentationParams(**{name: value}).validate()
    assert e.value.parameter == name


def test_plots_view_along_the_volume_up_with_colour_bars_and_labels_apart(tmp_path):
    """A y-down world (up = -y): the support plane is found along it, the three figures are written (top view
    along the up used, colour bars, colors.png with the surface colours), and labels of segments crowded
    together do not overlap."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from kinfu_cli.report.segment_plot import place_labels, plot_segments

    pts, nrm, col, _ = block_scene()
    R = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # z-up scene -> y-down world (z -> -y)
    opts = SegmentOptions(superquadrics=False, segmentation=SegmentationParams(up=(0.0, -1.0, 0.0), t_lccp=0.3))
    res = analyse_cloud(pts @ R.T, nrm @ R.T, opts, colors=col)
    assert res.segmentation.plane is not None and np.allclose(res.segmentation.plane[:3], [0, -1, 0], atol=1e-3)
    files = plot_segments(res, tmp_path)
    assert sorted(files) == ["colors.png", "saliency.png", "segments.png"]
    assert all(p.stat().st_size > 10_000 for p in files.values())
    fig, ax = plt.subplots()
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    fig.canvas.draw()
    boxes = place_labels(ax, [(0.5, 0.5 + 0.002 * i, f"{i}: 0.{i}") for i in range(12)])  # 12 labels, one spot
    assert not any(boxes[i].overlaps(boxes[j]) for i in range(12) for j in range(i))
    plt.close(fig)


def test_plot_axes_follow_the_scene_not_an_oversized_superquadric(tmp_path, monkeypatch):
    """A superquadric fitted to a wall may reach metres past the scene; the panels keep the scene's extent."""
    import dataclasses

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from kinfu_cli.report.segment_plot import plot_segments
    from kinfu_cli.segmentation.superquadric import Superquadric, SuperquadricFit

    pts, nrm, col, _ = block_scene()
    res = analyse_cloud(pts, nrm, SegmentOptions(superquadrics=False), colors=col)
    sid = res.saliency[0].id
    huge = Superquadric(np.array([4.0, 4.0, 4.0]), np.array([0.5, 0.5]), pts.mean(axis=0), np.eye(3))
    res = dataclasses.replace(res, superquadrics={sid: SuperquadricFit(huge, 0.0, 0.0, 10, 10, 0, 0.0, True)})
    made = []
    subplots = plt.subplots

    def spy(*a, **k):
        fig, axes = subplots(*a, **k)
        made.append(axes)
        return fig, axes

    monkeypatch.setattr(plt, "subplots", spy)
    plot_segments(res, tmp_path)
    span = np.ptp(pts, axis=0).max()
    for ax in made[0]:
        assert np.ptp(ax.get_xlim()) < 1.5 * span + 0.05 and np.ptp(ax.get_ylim()) < 1.5 * span + 0.05
