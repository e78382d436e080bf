"""`kinfu nbv --mode objects` says when its plan rests on part of the evidence, as the POI mode does.

Before: the segment planned for could be cut by a grid face (its far side never mapped, no contour point for it)
or have a third of its scored region outside the grid; the most salient segment could be passed over because all
its candidate views stood in unobserved space, the plan going to a less salient one; and "the objects are
considered reconstructed" could come from a fraction of the candidates. All silent.
"""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, save_ternary
from kinfu_cli.nbv.workflow import OUTSIDE_WARN_SHARE, rank_object_views

CAM = CameraModel(fx=40.0, fy=40.0, cx=31.5, cy=23.5, width=64, height=48, min_range=0.3)
VS = 0.02
TALL, SMALL = 1, 2  # the segments' ids: the small box is the more salient


def _two_boxes(x0=-1.3, y=0.5, blind=False) -> TernaryGrid:
    """A table top with a tall box (x = -0.35) and a small box (x = +0.35), each with its inner side unseen (their
    contour points); the grid spans x0..1.3 and -y..y. blind: the space where the small box's candidate views stand
    (x > 0.7, z > 0.4) was never observed."""
    n = (int(round((1.3 - x0) / VS)), int(round(2 * y / VS)), 60)
    origin = np.array([x0, -y, -0.2])
    lab = np.full(n, EMPTY, np.int8)
    x, y_, z = (origin + (np.indices(n).transpose(1, 2, 3, 0) + 0.5) * VS).transpose(3, 0, 1, 2)
    lab[z < 0.0] = UNKNOWN
    lab[(z < 0.04) & (z >= 0.0) & (np.abs(x) < 0.7) & (np.abs(y_) < 0.4)] = OCCUPIED
    lab[(np.abs(x + 0.35) < 0.08) & (np.abs(y_) < 0.08) & (z >= 0.04) & (z < 0.24)] = OCCUPIED
    lab[(np.abs(x - 0.35) < 0.05) & (np.abs(y_) < 0.05) & (z >= 0.04) & (z < 0.14)] = OCCUPIED
    lab[(x > -0.27) & (x < -0.15) & (np.abs(y_) < 0.12) & (z >= 0.04) & (z < 0.3)] = UNKNOWN
    lab[(x > 0.2) & (x < 0.3) & (np.abs(y_) < 0.1) & (z >= 0.04) & (z < 0.2)] = UNKNOWN
    if blind:
        lab[(x > 0.7) & (z > 0.4)] = UNKNOWN
    return TernaryGrid(lab, origin, VS, up=(0, 0, 1))


def _plan(tmp_path, grid, **kw):
    save_ternary(tmp_path / "ternary.npz", grid)
    views = rank_object_views(tmp_path / "ternary.npz", CAM, **kw)
    # a ternary grid has no fusion weights: said as ever, not one of these doubts
    return views, [w for w in views.warnings if "no fusion weights" not in w]


def test_a_plan_on_whole_objects_inside_the_grid_has_no_doubt(tmp_path):
    views, doubts = _plan(tmp_path, _two_boxes())
    assert views.plan.segment_id == SMALL and views.plan.score > 0
    assert doubts == []
    assert views.to_json()["attempts"][0]["touches_grid_faces"] == []


def test_the_most_salient_segment_passed_over_with_every_view_rejected_is_said(tmp_path):
    views, doubts = _plan(tmp_path, _two_boxes(blind=True))
    first, chosen = views.plan.attempts
    assert (first.segment_id, first.candidates, first.valid) == (SMALL, 40, 0)
    assert chosen.segment_id == TALL and views.plan.pose is not None
    assert doubts == [f"segment {SMALL} (40 candidates) passed over with every candidate view rejected "
                      f"(inside_unknown 40): no view of it was scored, and the plan is for the less salient "
                      f"segment {TALL}"]
    assert views.to_json()["attempts"][0]["rejected"]["inside_unknown"] == 40


def test_the_segment_planned_for_cut_by_a_grid_face_is_said(tmp_path):
    views, doubts = _plan(tmp_path, _two_boxes(x0=-0.4, blind=True))  # the tall box reaches x = -0.43
    assert views.plan.segment_id == TALL and views.plan.attempts[-1].touches_grid_faces == ["x-"]
    (cut,) = [w for w in doubts if w.startswith(f"segment {TALL}, the one planned for:")]
    assert "the grid cuts it at its x- face" in cut and "its views cover only the part inside the grid" in cut


def test_the_region_planned_for_mostly_outside_the_grid_is_said(tmp_path):
    views, doubts = _plan(tmp_path, _two_boxes(y=0.14))  # a 0.28 m grid across a 0.28 m region radius
    assert views.plan.segment_id == SMALL and views.plan.attempts[-1].touches_grid_faces == []
    (w,) = doubts
    share = int(w.split("for: ")[1].split(" %")[0])
    assert share >= 100 * OUTSIDE_WARN_SHARE
    assert f"% of the region its views are scored on (radius {views.plan.region_radius:.2f} m) lies outside" in w


def test_a_segment_passed_over_as_reconstructed_while_cut_by_the_grid_is_said(tmp_path):
    views, doubts = _plan(tmp_path, _two_boxes(x0=-0.4), score_threshold=1000.0)  # no view beats it: all passed
    assert views.plan.pose is None and [a.segment_id for a in views.plan.attempts] == [SMALL, TALL]
    assert doubts == [f"segment {TALL} (x- face) passed over as reconstructed though the grid cuts it there: beyond "
                      f"a face there is no voxel, so no contour point or score says that side is unseen (fuse again "
                      f"with a grid holding the whole object)"]


def test_a_reconstructed_verdict_with_a_segment_never_seen_by_a_valid_view_is_said(tmp_path):
    """The command: a `kinfu: warning:` line, the same text in views.json, exit 0."""
    save_ternary(tmp_path / "ternary.npz", _two_boxes(blind=True))
    res = CliRunner().invoke(cli, ["nbv", str(tmp_path / "ternary.npz"), "--mode", "objects", "--inc-th", "1000",
                                   "--fx", "40", "--fy", "40", "--cx", "31.5", "--cy", "23.5", "--width", "64",
                                   "--height", "48", "--quiet", "-o", str(tmp_path / "views.json")])
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "views.json").read_text())
    assert doc["pose"] is None
    total = sum(a["candidates"] for a in doc["attempts"])
    (w,) = [w for w in doc["warnings"] if w.startswith("no view scores above 1000")]
    assert w.startswith(f"no view scores above 1000, judged from only {total - 56} valid of {total} candidate views")
    assert f"(rejected: below_table 16, inside_unknown 40; segment {SMALL} had none)" in w
    assert f"kinfu: warning: {w}" in res.stderr.splitlines()


@pytest.mark.parametrize("threshold", [0.0, 1000.0])
def test_no_doubt_when_every_candidate_was_rejected_is_said_once(tmp_path, threshold):
    """Every candidate rejected is the plan's empty reason already: not said again per segment."""
    views, doubts = _plan(tmp_path, _two_boxes(), table_z=5.0, score_threshold=threshold)
    assert views.empty_reason and "all" in views.empty_reason and "below_table" in views.empty_reason
    assert doubts == [views.empty_reason]
