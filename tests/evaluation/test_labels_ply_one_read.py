"""An ascii labels PLY is read once: plyfile reads its rows from a text stream, and the rows beyond the header's
count are counted on the same stream (the file was read a second time for that). CR-only line ends are counted
too: the second read looked for end_header after a LF and checked nothing when it found none, so a CR-ended
file with more rows than declared was read as its first N points."""

from __future__ import annotations

import builtins
import io

import numpy as np
import pytest

from kinfu_cli.io.labelled_cloud import LabelsFileError, read_labelled_cloud

ROWS = ["0 0 0 1", "0.1 0 0 2", "0.2 0 0 0"]


def _ascii_ply(path, declared: int, newline: str = "\n", tail: str = ""):
    header = ["ply", "format ascii 1.0", f"element vertex {declared}", "property float x", "property float y",
              "property float z", "property int label", "end_header"]
    path.write_bytes((newline.join(header + ROWS) + newline + tail).encode())
    return path


def _count_opens(monkeypatch, path) -> list:
    """Every open of `path` (builtins.open and io.open, which pathlib's read_bytes goes through)."""
    opened = []
    real = builtins.open

    def counting(file, *args, **kw):
        if str(file) == str(path):
            opened.append(args[0] if args else kw.get("mode", "r"))
        return real(file, *args, **kw)

    monkeypatch.setattr(builtins, "open", counting)
    monkeypatch.setattr(io, "open", counting)
    return opened


@pytest.mark.parametrize("declared", [3, 2], ids=["counts agree", "one more row"])
def test_an_ascii_ply_is_opened_once(tmp_path, monkeypatch, declared):
    path = _ascii_ply(tmp_path / "labels.ply", declared, tail="\n")
    opened = _count_opens(monkeypatch, path)
    if declared == 3:
        assert read_labelled_cloud(path).labels.tolist() == [1, 2, 0]
    else:
        with pytest.raises(LabelsFileError, match="element vertex 2 but the file holds 1 more row: a wrong count"):
            read_labelled_cloud(path)
    assert len(opened) == 1, opened


@pytest.mark.parametrize("newline", ["\n", "\r\n", "\r"], ids=["lf", "crlf", "cr"])
def test_rows_beyond_the_count_are_refused_whatever_the_line_end(tmp_path, newline):
    path = _ascii_ply(tmp_path / "labels.ply", 1, newline, tail=newline * 2)
    with pytest.raises(LabelsFileError, match="element vertex 1 but the file holds 2 more rows"):
        read_labelled_cloud(path)
    whole = _ascii_ply(tmp_path / "whole.ply", 3, newline, tail=f"  {newline}{newline}")
    cloud = read_labelled_cloud(whole)
    assert cloud.labels.tolist() == [1, 2, 0] and np.allclose(cloud.points[:, 0], [0, 0.1, 0.2])
