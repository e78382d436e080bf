"""A binary PLY with a line end after its last row (a text tool's habit) is read, not refused as a wrong count in
the header; bytes that are not whitespace after the rows still are."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.io.labelled_cloud import MAX_TRAILING_WHITESPACE, LabelsFileError, read_labelled_cloud
from kinfu_cli.localization.mesh_model import LocalizationError
from kinfu_cli.localization.points import read_points

ROWS = 10
HEADER = ("ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n"
          "property float z\nproperty int label\nend_header\n")


def _binary_ply(path, tail: bytes):
    rows = np.zeros(ROWS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("label", "<i4")])
    rows["x"] = np.linspace(0.0, 0.1, ROWS)
    rows["label"] = np.arange(ROWS) % 3
    path.write_bytes(HEADER.format(n=ROWS).encode() + rows.tobytes() + tail)
    return path


@pytest.mark.parametrize("tail", [b"\n", b"\r\n", b"  \n", b"\n\n"], ids=["lf", "crlf", "spaces", "two-lf"])
def test_trailing_whitespace_is_no_count_error(tmp_path, tail):
    path = _binary_ply(tmp_path / "pts.ply", tail)
    cloud = read_labelled_cloud(path)
    assert len(cloud.labels) == ROWS and cloud.labels.tolist() == (np.arange(ROWS) % 3).tolist()
    pts = read_points(path)  # kinfu localize's measured points
    assert pts.shape == (ROWS, 3) and np.allclose(pts[:, 0], np.linspace(0.0, 0.1, ROWS))


@pytest.mark.parametrize("tail, extra", [(b"\nx", "2 more bytes"), (b"\n" * (MAX_TRAILING_WHITESPACE + 1),
                                                                      f"{MAX_TRAILING_WHITESPACE + 1} more bytes")])
def test_more_than_a_line_end_is_still_a_count_error(tmp_path, tail, extra):
    path = _binary_ply(tmp_path / "pts.ply", tail)
    with pytest.raises(LabelsFileError, match=f"holds {extra}: a wrong count"):
        read_labelled_cloud(path)
    with pytest.raises(LocalizationError, match=f"holds {extra}"):
        read_points(path)
