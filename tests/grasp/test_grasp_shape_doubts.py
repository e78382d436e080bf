"""`kinfu grasp` on shapes segments.json doubts: an oversized superquadric (far larger than its points' box) is
skipped, a fit that did not converge and a segment the grid cuts off are grasped with a warning naming them, and
a scene without objects says so instead of asking for superquadrics that ran."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.conftest import one_line_error

BOX = [0.04, 0.03, 0.05, 0.5, 0.5, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0]
POINTS_BOX = {"center": [0.0, 0.0, 0.05], "axes": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "extents": [0.08, 0.06, 0.1]}
PLANE = {"id": 0, "kind": "support_plane", "superquadric": None}


def _segment(sid: int, params=BOX, box=POINTS_BOX, **extra) -> dict:
    return {"id": sid, "kind": "object", "superquadric": {"params": list(params), **extra}, "oriented_box": box,
            "touches_grid_faces": []}


def _run(tmp_path, segments: list[dict], **doc):
    path = tmp_path / "segments.json"
    path.write_text(json.dumps({"segments": segments, "support_plane": [0.0, 0.0, 1.0, 0.0], **doc}))
    out = tmp_path / "g.json"
    res = CliRunner().invoke(cli, ["grasp", str(tmp_path), "-o", str(out), "--quiet", "--starts", "1"])
    return res, path, out


def test_a_superquadric_three_times_its_points_is_skipped_as_oversized(tmp_path):
    """The plate of the fuzz report: points 0.19 x 0.13 x 0 m, a converged fit 0.52 x 0.004 x 0.55 m, grasped."""
    plate = {"center": [0.3, 0.0, 0.1], "axes": [[1, 0, 0], [0, 0, 1], [0, 1, 0]], "extents": [0.19, 0.13, 0.0]}
    disc = [0.261, 0.002, 0.274, 0.5, 0.5, 0.3, 0.0, 0.1, 0.0, 0.0, 0.0]
    res, _, out = _run(tmp_path, [_segment(3), _segment(1, disc, plate, converged=True)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert [g["segment"] for g in doc["grasps"]] == [3]
    (skipped,) = doc["skipped_segments"]
    assert skipped["segment"] == 1 and "2.9x the largest side of the box of its points (0.19 m" in skipped["reason"]
    assert "oversized" in skipped["reason"]
    assert any(w.startswith("segment 1: its superquadric's largest side 0.548 m") for w in doc["warnings"])


def test_grasps_on_an_unconverged_fit_or_a_cut_segment_are_said(tmp_path):
    shifted = BOX[:5] + [0.3, 0.0, 0.05] + BOX[8:]
    box = {**POINTS_BOX, "center": [0.3, 0.0, 0.05]}
    cut = {**_segment(5, shifted, box, converged=True), "touches_grid_faces": ["z+", "x-"]}
    res, _, out = _run(tmp_path, [_segment(2, converged=False, residual=0.019), cut])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert sorted(g["segment"] for g in doc["grasps"]) == [2, 5] and doc["skipped_segments"] == []
    warned = [ln for ln in res.output.splitlines() if ln.startswith("kinfu: warning:")]
    assert "kinfu: warning: segment 2 (residual 19 mm): the superquadric fit did not converge" in "\n".join(warned)
    assert "kinfu: warning: segment 5 (z+, x-) touches the grid's faces" in "\n".join(warned)
    assert len(warned) == 2 and len(doc["warnings"]) == 2
    flags = {g["segment"]: (g["touches_grid_faces"], g["fit_converged"]) for g in doc["grasps"]}
    assert flags == {2: ([], False), 5: (["z+", "x-"], True)}  # on each grasp too, not only in a warning


def test_a_scene_without_objects_says_so_not_run_with_superquadrics(tmp_path):
    said = ("no objects: the support plane's segment holds all 2017 surface points; no point rises more than "
            "0.02 m (2 x plane_distance) above the plane")
    res, path, out = _run(tmp_path, [PLANE], warnings=[said], options={"superquadrics": True})
    line = one_line_error(res, str(path), "no object segment to grasp: kinfu segment found none (no point rises")
    assert "with superquadrics" not in line and not out.exists()


def test_segments_whose_fits_all_failed_name_the_reason(tmp_path):
    failed = {"id": 4, "kind": "object", "superquadric": None, "superquadric_error": "12 points (< sq_min_points 30)"}
    res, path, _ = _run(tmp_path, [failed, PLANE], options={"superquadrics": True})
    line = one_line_error(res, str(path), "no object segment has a superquadric to grasp (of 1; segment 4: 12 points")
    assert "with superquadrics" not in line
    res, path, _ = _run(tmp_path, [{**failed, "superquadric_error": None}, PLANE], options={"superquadrics": False})
    one_line_error(res, "segmented without them: run kinfu segment with superquadrics")
