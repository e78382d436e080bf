"""localize --segments: a segments.json whose segments are not objects, or nested too deep to read, is the one
LocalizationError naming the file (AttributeError / RecursionError tracebacks before)."""

from __future__ import annotations

import pytest

from kinfu_cli.localization.points import LocalizationError, read_segment_points


@pytest.mark.parametrize("text", ['{"segments": [5, 6]}', "[" * 100_000 + "]" * 100_000])
def test_a_damaged_segments_json_is_a_localization_error(tmp_path, text):
    path = tmp_path / "segments.json"
    path.write_text(text)
    with pytest.raises(LocalizationError) as err:
        read_segment_points(path, 1)
    assert str(path) in str(err.value)
