"""`kinfu grasp` on hand-edited or damaged segments.json: one `kinfu: error:` line naming the file and the entry,
never a traceback; an extreme but valid superquadric ends without numpy warnings."""

from __future__ import annotations

import json
import warnings

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.conftest import one_line_error

BOX = [0.04, 0.03, 0.05, 0.5, 0.5, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0]


def _doc(**segment):
    seg = {"id": 3, "kind": "object", "superquadric": {"params": BOX}}
    seg.update(segment)
    return {"segments": [seg], "support_plane": [0.0, 0.0, 1.0, 0.0]}


@pytest.mark.parametrize("doc, needle", [
    ({"segments": [5]}, "segments[0] is int"),
    (_doc(id="abc"), "segments[0].id is 'abc'"),
    (_doc(id=None), "segments[0].id is None"),
    (_doc(id=2.5), "segments[0].id is 2.5"),
    (_doc(multi_superquadric=[1, 2]), "multi_superquadric"),
    (_doc(multi_superquadric={"parts": {"a": 1}}), "multi_superquadric"),
    ({**_doc(), "support_plane": ["a", "b", "c", "d"]}, "support_plane"),
    ({**_doc(), "support_plane": [[1, 2], [3]]}, "support_plane"),
    (_doc(superquadric={"params": [1e300] * 11}), "out of range"),
])
def test_a_damaged_segments_json_is_one_line_naming_the_file(tmp_path, doc, needle):
    path = tmp_path / "segments.json"
    path.write_text(json.dumps(doc))
    res = CliRunner().invoke(cli, ["grasp", str(path), "-o", str(tmp_path / "g.json"), "--quiet", "--starts", "1"])
    one_line_error(res, str(path), needle)
    assert not (tmp_path / "g.json").exists()


def test_an_extreme_superquadric_ends_without_numpy_warnings(tmp_path):
    """Exponents at the allowed ends overflow the inside-outside function: no grasp, but no RuntimeWarning."""
    path = tmp_path / "segments.json"
    path.write_text(json.dumps(_doc(superquadric={"params": [1e-6, 1e-6, 1e-6, 0.01, 0.01, 0, 0, 0.05, 0, 0, 0]})))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = CliRunner().invoke(cli, ["grasp", str(path), "-o", str(tmp_path / "g.json"), "--quiet", "--starts", "1"])
    assert res.exit_code == 0, res.output
    assert all(line.startswith("kinfu: warning: ") for line in res.output.splitlines() if line.strip()), res.output
