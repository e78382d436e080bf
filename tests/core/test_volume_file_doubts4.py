"""A volume file's metadata is checked against the bounds fusion puts on a grid (truncation, voxel edge and depth
range up to 100 m): a 200 m truncation passed the file check and failed in TernaryVolume without the file."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.volume_file import read_volume_file, write_volume_file
from kinfu_cli.fusion.volume import TernaryVolume, load_volume
from tests.conftest import one_line_error


def _volume_with(tmp_path, **meta):
    vol = TernaryVolume(size=(0.4, 0.4, 0.4), voxel_size=0.02)
    path = vol.save(tmp_path / "v.npz")
    doc, arrays = read_volume_file(path)
    doc.update(meta)
    return write_volume_file(tmp_path / "bad.npz", doc, arrays)


@pytest.mark.parametrize("key,value", [("truncation", 200.0), ("voxel_size", 150.0), ("max_depth", 500.0)])
def test_a_value_between_fusions_bound_and_1000_m_names_the_file(tmp_path, key, value):
    path = _volume_with(tmp_path, **{key: value})
    with pytest.raises(VolumeError, match=rf"bad\.npz: volume metadata '{key}' is {value}, expected .*100\]"):
        load_volume(path)


def test_segment_of_a_200_m_truncation_names_the_file(tmp_path):
    path = _volume_with(tmp_path, truncation=200.0)
    res = CliRunner().invoke(cli, ["segment", str(path), "-o", str(tmp_path / "sg"), "--quiet"])
    one_line_error(res, "bad.npz", "'truncation'", "200.0")


def test_a_100_m_truncation_still_loads(tmp_path):
    assert load_volume(_volume_with(tmp_path, truncation=100.0)).truncation == 100.0
