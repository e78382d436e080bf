"""`kinfu grasp` on doubtful segments.json: two segments with one id are refused naming the file; a superquadric
whose centre lies outside its points' box (grown by its size) is skipped with a warning naming the segment and
listed in skipped_segments, instead of a grasp of empty space that looks like any other."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.conftest import one_line_error

BOX = [0.04, 0.03, 0.05, 0.5, 0.5, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0]
POINTS_BOX = {"center": [0.0, 0.0, 0.05], "axes": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "extents": [0.08, 0.06, 0.1]}


def _segment(sid: int, params=BOX, box=POINTS_BOX) -> dict:
    return {"id": sid, "kind": "object", "superquadric": {"params": list(params)}, "oriented_box": box}


def _run(tmp_path, segments: list[dict]):
    path = tmp_path / "segments.json"
    path.write_text(json.dumps({"segments": segments, "support_plane": [0.0, 0.0, 1.0, 0.0]}))
    out = tmp_path / "g.json"
    res = CliRunner().invoke(cli, ["grasp", str(tmp_path), "-o", str(out), "--quiet", "--starts", "1"])
    return res, path, out


def test_two_segments_with_one_id_are_refused_naming_the_file(tmp_path):
    shifted = BOX[:5] + [0.3, 0.0, 0.05] + BOX[8:]
    box = {**POINTS_BOX, "center": [0.3, 0.0, 0.05]}
    res, path, out = _run(tmp_path, [_segment(3), _segment(3, shifted, box)])
    one_line_error(res, str(path), "segments[1].id 3 repeats segments[0].id")
    assert not out.exists()


def test_a_superquadric_far_from_its_points_is_skipped_with_a_warning(tmp_path):
    far = BOX[:5] + [10.0, 0.0, 0.05] + BOX[8:]  # its points' box stays at the origin
    res, _, out = _run(tmp_path, [_segment(3), _segment(7, far)])
    assert res.exit_code == 0, res.output
    warned = [line for line in res.output.splitlines() if line.startswith("kinfu: warning: segment 7:")]
    assert len(warned) == 1 and "outside the box of its points" in warned[0], res.output
    doc = json.loads(out.read_text())
    assert [g["segment"] for g in doc["grasps"]] == [3]
    assert [s["segment"] for s in doc["skipped_segments"]] == [7]
    assert any(w.startswith("segment 7:") for w in doc["warnings"])


def test_a_superquadric_inside_its_grown_box_is_grasped(tmp_path):
    near = BOX[:5] + [0.08, 0.0, 0.05] + BOX[8:]  # 0.04 m past the box's side, within its 0.05 m size
    res, _, out = _run(tmp_path, [_segment(3, near)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["skipped_segments"] == [] and [g["segment"] for g in doc["grasps"]] == [3]


def test_only_far_superquadrics_is_one_line_naming_the_segment(tmp_path):
    far = BOX[:5] + [0.0, 0.0, 10.05] + BOX[8:]
    res, path, out = _run(tmp_path, [_segment(5, far)])
    one_line_error(res, str(path), "segment 5", "outside the box of its points")
    assert not out.exists()
