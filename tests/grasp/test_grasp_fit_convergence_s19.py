"""`kinfu grasp` on fits segments.json says did not converge: a segment grasped on its multi-superquadric's parts
is doubted for its parts' fits (the warning and the grasp's fit_converged agree), not for the single fit it no longer
uses, and a residual segments.json holds as a 400-digit integer does not end the run in a traceback."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli

BOX = [0.04, 0.03, 0.05, 0.5, 0.5, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0]
LOWER = [0.04, 0.03, 0.025, 0.5, 0.5, 0.0, 0.0, 0.025, 0.0, 0.0, 0.0]
UPPER = [0.04, 0.03, 0.025, 0.5, 0.5, 0.0, 0.0, 0.075, 0.0, 0.0, 0.0]
POINTS_BOX = {"center": [0.0, 0.0, 0.05], "axes": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "extents": [0.08, 0.06, 0.1]}


def _segment(sid: int, converged: bool, parts_converged: tuple[bool, ...] | None = None, residual=0.019) -> dict:
    s = {"id": sid, "kind": "object", "oriented_box": POINTS_BOX, "touches_grid_faces": [],
         "superquadric": {"params": BOX, "converged": converged, "residual": residual}}
    if parts_converged is not None:
        s["multi_superquadric"] = {"parts": [{"params": p, "converged": c, "residual": 0.003}
                                             for p, c in zip((LOWER, UPPER), parts_converged)]}
    return s


def _grasp(tmp_path, segments: list[dict]):
    (tmp_path / "segments.json").write_text(json.dumps({"segments": segments, "support_plane": [0.0, 0.0, 1.0, 0.0]}))
    out = tmp_path / "g.json"
    res = CliRunner().invoke(cli, ["grasp", str(tmp_path), "-o", str(out), "--quiet", "--starts", "1"])
    assert res.exit_code == 0, res.output
    warned = [ln for ln in res.output.splitlines() if ln.startswith("kinfu: warning:")]
    return warned, json.loads(out.read_text())


def test_a_multi_superquadric_segment_is_doubted_for_its_parts_fits_not_its_single_fit(tmp_path):
    warned, doc = _grasp(tmp_path, [_segment(4, converged=True, parts_converged=(True, False))])
    assert warned == ["kinfu: warning: segment 4 (part 1, residual 3 mm): the superquadric fit did not converge: its "
                      "grasp rests on an unfinished shape"]
    assert doc["grasps"][0]["fit_converged"] is False

    # its single fit did not converge, its parts did: the grasp rests on the parts, nothing to doubt
    warned, doc = _grasp(tmp_path, [_segment(4, converged=False, parts_converged=(True, True))])
    assert warned == [] and doc["warnings"] == []
    assert doc["grasps"][0]["fit_converged"] is True


def test_a_residual_of_400_digits_is_left_out_of_the_warning(tmp_path):
    (tmp_path / "segments.json").write_text(
        json.dumps({"segments": [_segment(2, converged=False)], "support_plane": [0.0, 0.0, 1.0, 0.0]})
        .replace('"residual": 0.019', '"residual": ' + "9" * 400))
    res = CliRunner().invoke(cli, ["grasp", str(tmp_path), "-o", str(tmp_path / "g.json"), "--quiet", "--starts", "1"])
    assert res.exit_code == 0 and res.exception is None, res.output
    assert "kinfu: warning: segment 2: the superquadric fit did not converge: its grasp rests" in res.output
