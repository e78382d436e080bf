"""eval segment reads the segments.json beside a segments.ply and the changes.json beside the labels: damaged
ones are a one-line LabelsFileError naming the file, or ignored where the names are optional (they were
tracebacks: a JSON list, an 'up' of strings, deep nesting, 'objects' a string)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinfu_cli.evaluation.segment_eval import label_names, load_predicted_segments
from kinfu_cli.io.labelled_cloud import LabelsFileError, write_labelled_cloud


@pytest.mark.parametrize("text, needle", [
    ("[1, 2]", "expected the JSON object"),
    (json.dumps({"up": ["a", "b", "c"]}), "'up'"),
    (json.dumps({"up": [0, 0, 0]}), "'up'"),
    ("[" * 100_000 + "]" * 100_000, "not readable JSON"),
])
def test_a_damaged_segments_json_beside_the_cloud_is_one_error(tmp_path, text, needle):
    write_labelled_cloud(tmp_path / "segments.ply", np.random.default_rng(0).random((20, 3)), np.arange(20) % 3)
    (tmp_path / "segments.json").write_text(text)
    with pytest.raises(LabelsFileError) as err:
        load_predicted_segments(tmp_path / "segments.ply")
    assert str(tmp_path / "segments.json") in str(err.value) and needle in str(err.value)


def test_label_names_ignore_a_damaged_changes_json(tmp_path):
    (tmp_path / "changes.json").write_text(json.dumps({"objects": "abc"}))
    assert label_names(tmp_path / "labels.ply") == {}
