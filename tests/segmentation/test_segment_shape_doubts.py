"""What `kinfu segment` says about doubtful shapes: a superquadric far larger than its points (oversized), segments
the grid cuts off (touches_grid_faces), why a support plane left no object, no numpy warning on a collinear
remainder, and a too wide isolation threshold refused before the segmentation runs."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.segmentation import pipeline
from kinfu_cli.segmentation.pipeline import SegmentOptions, segment_volume, support_plane_warnings
from kinfu_cli.segmentation.segments import Segmentation, SegmentationParams, detect_support_plane

UP = np.array([0.0, 0.0, 1.0])


def _table(shape=(100, 100, 60)) -> np.ndarray:
    """1 cm labels: unknown below a table top at z index 10, empty above it."""
    t = np.zeros(shape, np.int8)
    t[:, :, 11:] = -1
    t[5:shape[0] - 5, 5:shape[1] - 5, 10] = 1
    return t


def _grid(labels, origin=(-0.5, -0.5, 0.6)) -> TernaryGrid:
    return TernaryGrid(labels, np.asarray(origin, dtype=np.float64), 0.01, up=UP)


def test_a_superquadric_three_times_its_plate_is_flagged_oversized():
    """A 1-voxel sheet 19 x 19 cm: its fit was a 0.55 m disc, converged with residual 0, and said nothing."""
    t = _table()
    t[30, 20:40, 11:30] = 1
    doc = segment_volume(_grid(t)).to_json()
    sheet = next(s for s in doc["segments"] if s["kind"] == "object" and s["point_count"] > 200)
    sq = sheet["superquadric"]
    assert sq["oversized"] is True and sq["box_ratio"] > 2.5
    (said,) = [w for w in doc["warnings"] if "oversized" in w]
    assert said.startswith(f"segment {sheet['id']} (0.55 m on a 0.19 m box, 2.9x)")
    others = [s["superquadric"] for s in doc["segments"] if s["kind"] == "object" and s["id"] != sheet["id"]]
    assert all(not q["oversized"] and q["box_ratio"] < 1.6 for q in others if q)


def test_segments_cut_by_a_grid_face_are_flagged_but_not_on_the_floor_face():
    t = np.full((50, 50, 30), -1, np.int8)
    t[:, :, 0] = 1  # the table fills the grid's bottom layer: objects on it touch the z- face, uncut
    t[20:30, 20:30, 1:10] = 1  # inside
    t[0:8, 35:45, 1:10] = 1  # cut by x-
    t[35:45, 5:15, 1:] = 1  # cut by z+
    result = segment_volume(_grid(t, origin=(0.0, 0.0, 0.0)), SegmentOptions(superquadrics=False))
    doc = result.to_json()
    centres = {"inside": (0.25, 0.25), "x-": (0.04, 0.4), "z+": (0.4, 0.1)}  # the boxes' (x, y)
    faces = {min(centres, key=lambda k: np.hypot(*(np.asarray(centres[k]) - s["centroid"][:2]))):
             s["touches_grid_faces"] for s in doc["segments"] if s["kind"] == "object"}
    assert faces == {"inside": [], "x-": ["x-"], "z+": ["z+"]}
    cut = {s["id"]: s["touches_grid_faces"] for s in doc["segments"] if s.get("touches_grid_faces")}
    (said,) = [w for w in doc["warnings"] if "touches_grid_faces" in w]
    assert said.startswith("segments " + ", ".join(f"{i} ({f[0]})" for i, f in sorted(cut.items())))


def _seg(points, labels, plane=(0.0, 0.0, 1.0, 0.0), up=(0.0, 0.0, 1.0)) -> Segmentation:
    n = len(labels)
    return Segmentation(points=np.asarray(points, dtype=np.float64), normals=np.zeros((n, 3)),
                        labels=np.asarray(labels), plane=np.asarray(plane), supervoxels=-np.ones(n, int),
                        n_supervoxels=0, stats={"support_plane_search": {"up": list(up)}})


def test_no_objects_names_its_cause_and_blames_the_up_only_for_points_below_the_plane():
    flat = np.c_[np.random.default_rng(0).uniform(0, 1, (400, 2)), np.zeros(400)]
    (bare,) = support_plane_warnings(_seg(flat, [0] * 400), "volume")
    assert "all 400 surface points" in bare and "no point rises more than 0.02 m" in bare
    assert "flipped" not in bare
    rod = np.c_[np.full(30, 0.5), np.full(30, 0.5), np.linspace(0.03, 0.29, 30)]  # a 1-voxel rod, dropped
    (thin,) = support_plane_warnings(_seg(np.vstack([flat, rod]), [0] * 400 + [-1] * 30), "volume")
    assert "400 of 430 surface points (30 dropped as specks)" in thin
    assert "30 points rise up to 0.29 m above" in thin and "min_segment_points 50" in thin and "flipped" not in thin
    below = np.c_[np.random.default_rng(1).uniform(0.3, 0.5, (100, 2)), np.full(100, -0.1)]
    (flipped,) = support_plane_warnings(_seg(np.vstack([flat, below]), [0] * 500), "volume")
    assert "100 points lie up to 0.1 m below the plane facing up [0.0, 0.0, 1.0] (the volume's)" in flipped
    assert "flipped" in flipped


def test_collinear_points_left_after_the_table_raise_no_numpy_warning():
    """RANSAC on a rod's points (all collinear) has no plane: the support search divided by a zero normal and
    numpy's RuntimeWarning reached stderr."""
    rng = np.random.default_rng(0)
    table = np.c_[rng.uniform(0, 1, (2000, 2)), np.zeros(2000)]
    rod = np.c_[np.linspace(0.2, 0.5, 80), np.full(80, 0.5), np.full(80, 0.2)]
    points = np.vstack([table, rod])
    normals = np.tile(UP, (len(points), 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plane, inliers = detect_support_plane(points, normals, SegmentationParams(up=tuple(UP)))
    assert plane is not None and abs(plane[3]) < 1e-9 and inliers[:2000].all() and not inliers[2000:].any()


def test_a_rod_segmented_through_the_cli_leaves_stderr_clean(tmp_path):
    t = _table()
    t[60, 60, 11:40] = 1
    save_ternary(tmp_path / "rod.npz", _grid(t))
    with warnings.catch_warnings():  # pytest records warnings instead of printing them: make them fail the run
        warnings.simplefilter("error")
        res = CliRunner().invoke(cli, ["segment", str(tmp_path / "rod.npz"), "-o", str(tmp_path / "s"), "--quiet",
                                       "--min-segment-points", "1", "--fragment-points", "0", "--no-superquadrics"])
    assert res.exit_code == 0 and res.stderr == "", res.stderr


def test_an_isolation_threshold_spanning_the_cloud_is_refused_before_segmenting(monkeypatch):
    def never(*args, **kwargs):
        raise AssertionError("segment_cloud ran")

    monkeypatch.setattr(pipeline, "segment_cloud", never)
    points = np.random.default_rng(0).uniform(0, 1, (8000, 3))
    with pytest.raises(ConfigError) as err:
        pipeline.analyse_cloud(points, np.tile(UP, (8000, 1)), SegmentOptions(isolation_threshold=5.0))
    assert err.value.parameter == "isolation_threshold" and "among the 8000 surface points" in str(err.value)
