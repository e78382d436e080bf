"""The JSON inputs kinfu reads (pois.json, nbv --candidates, segments.json for grasp and eval segment) fail as
their own one-line errors on every JSON the standard library refuses, not only on syntax errors: an integer of
more than 4300 digits raises a bare ValueError, deep nesting a RecursionError."""

from __future__ import annotations

import pytest

from kinfu_cli.core.errors import KinfuError
from kinfu_cli.core.pois import read_pois
from kinfu_cli.grasp.plan import read_segments
from kinfu_cli.nbv.viewpoints import read_candidates

BIG = "1" + "0" * 5000
TEXTS = {
    "huge integer": '{"pois": [{"position": [%s, 0, 0]}], "segments": [], "poses": [[%s]]}' % (BIG, BIG),
    "deep nesting": "[" * 100_000 + "]" * 100_000,
}


@pytest.mark.parametrize("reader", [read_pois, read_candidates, read_segments])
@pytest.mark.parametrize("what", sorted(TEXTS))
def test_unreadable_json_is_the_readers_error_naming_the_file(tmp_path, reader, what):
    path = tmp_path / "input.json"
    path.write_text(TEXTS[what])
    with pytest.raises(KinfuError) as err:
        reader(path)
    assert str(path) in str(err.value)
