"""eval fusion reads the report.json of a `kinfu fuse` folder for provenance only: a hand-edited one ("frames" a
number, "pose_mode" a list, a JSON list) is ignored, not an AttributeError / TypeError traceback."""

from __future__ import annotations

import json

import pytest

from kinfu_cli.evaluation.reconstruction import fused_window, report_json_of


@pytest.mark.parametrize("doc, window", [
    ({"frames": 5}, None),
    ({"frames": {"start_s": "a", "end_s": [1]}}, None),
    ({"frames": {"start_s": 1.5, "end_s": float("nan")}}, (1.5, None)),
    ({"frames": {"start_s": 1.5, "end_s": 4}}, (1.5, 4)),
    ([1, 2], None),
])
def test_a_hand_edited_report_gives_no_window_instead_of_a_traceback(tmp_path, doc, window):
    (tmp_path / "report.json").write_text(json.dumps(doc))
    assert fused_window(report_json_of(tmp_path)) == window
