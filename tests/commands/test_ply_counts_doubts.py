"""A PLY whose header counts disagree with its rows is refused, naming the file, where kinfu reads PLY clouds:
labelled clouds (`kinfu eval segment`) and measured points (`kinfu localize`). More rows than `element vertex N`
were read as the first N points with no word; fewer fail with the declared and the found count."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.io.labelled_cloud import LabelsFileError, read_labelled_cloud
from kinfu_cli.localization.mesh_model import LocalizationError
from kinfu_cli.localization.points import read_points

ROWS = 10
HEADER = ("ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
          "property int label\nend_header\n")


def _points() -> np.ndarray:
    return np.random.default_rng(0).random((ROWS, 3)) * 0.1


def write_ply(path, declared: int, binary: bool, trailing_blank: bool = False):
    """ROWS vertices (x, y, z, label) under a header declaring `declared`."""
    pts, labels = _points(), np.arange(ROWS) % 3
    if binary:
        rows = np.zeros(ROWS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("label", "<i4")])
        rows["x"], rows["y"], rows["z"], rows["label"] = *pts.T, labels
        path.write_bytes(HEADER.format(fmt="binary_little_endian", n=declared).encode() + rows.tobytes())
    else:
        body = "".join(f"{x} {y} {z} {k}\n" for (x, y, z), k in zip(pts, labels))
        path.write_text(HEADER.format(fmt="ascii", n=declared) + body + ("\n\n" if trailing_blank else ""))
    return path


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
@pytest.mark.parametrize("declared, detail", [(1000, "declares 1000 vertex rows"), (5, "5 more")],
                         ids=["fewer rows", "more rows"])
def test_reader_refuses_counts_that_disagree(tmp_path, binary, declared, detail):
    path = write_ply(tmp_path / "cloud.ply", declared, binary)
    with pytest.raises(LabelsFileError, match=detail) as info:
        read_labelled_cloud(path)
    assert str(path) in str(info.value) and f"element vertex {declared}" in str(info.value)
    with pytest.raises(LocalizationError, match=detail):
        read_points(path)


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_matching_counts_read_every_row(tmp_path, binary):
    path = write_ply(tmp_path / "cloud.ply", ROWS, binary, trailing_blank=not binary)
    cloud = read_labelled_cloud(path)
    assert len(cloud.points) == ROWS and cloud.labels.tolist() == (np.arange(ROWS) % 3).tolist()
    assert len(read_points(path)) == ROWS


def test_eval_segment_names_the_file(tmp_path):
    seg = write_ply(tmp_path / "segments.ply", 5, binary=True)
    gt = tmp_path / "labels.npz"
    np.savez(gt, points=_points(), labels=np.arange(ROWS) % 3)
    res = CliRunner().invoke(cli, ["eval", "segment", str(seg), "--ground-truth", str(gt)])
    one_line_error(res, str(seg), "element vertex 5", "5 more vertex rows")


def test_localize_names_the_file(sample_dir, tmp_path):
    points = write_ply(tmp_path / "touches.ply", 5, binary=False)
    model = sample_dir / "ground_truth" / "objects" / "obj1.ply"
    res = CliRunner().invoke(cli, ["localize", str(model), str(points), "--particles", "20"])
    one_line_error(res, str(points), "element vertex 5", "5 more rows")


def test_segment_points_name_the_segments_ply_once(tmp_path):
    from kinfu_cli.localization.points import read_segment_points

    (tmp_path / "segments.json").write_text('{"segments": [{"id": 1, "kind": "object", "point_count": 10}]}')
    rows = np.zeros(ROWS, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"),
                                 ("blue", "u1")])
    rows["x"], rows["y"], rows["z"] = _points().T
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
              "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    ply = tmp_path / "segments.ply"
    ply.write_bytes(header.encode() + rows.tobytes())
    with pytest.raises(LocalizationError, match="6 more vertex rows") as info:
        read_segment_points(tmp_path / "segments.json", 1)
    assert str(info.value).count(str(ply)) == 1
