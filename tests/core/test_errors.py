"""Library errors name Python parameters; the CLI shows the running command's flag for them."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError, KinfuError
from kinfu_cli.core.grid import TernaryGrid, save_ternary


def test_parameter_errors_read_parameter_colon_detail():
    err = ConfigError("expected a positive distance in metres, got 0", parameter="radius")
    assert str(err) == "radius: expected a positive distance in metres, got 0"
    assert err.parameter == "radius" and err.detail.startswith("expected")
    assert str(KinfuError("plain")) == "plain" and KinfuError("plain").parameter is None


@pytest.fixture
def volume(tmp_path):
    labels = np.zeros((8, 8, 8), np.int8)
    save_ternary(tmp_path / "t.npz", TernaryGrid(labels, (0, 0, 0), 0.05))
    return tmp_path / "t.npz"


@pytest.mark.parametrize("args, line", [
    (["--vfov-extra", "50"], "kinfu: error: --vfov-extra: expected 0 to 45 degrees, got 50.0"),
    (["--fx", "0", "--fy", "1", "--cx", "1", "--cy", "1"], "kinfu: error: --fx: expected a positive focal length"),
    (["--min-range", "5", "--max-range", "1"], "kinfu: error: --min-range/--max-range: expected 0 <= min < max"),
])
def test_cli_shows_the_flag_of_a_library_parameter(volume, args, line):
    res = CliRunner().invoke(cli, ["nbv", str(volume), "--mode", "objects", *args])
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == [res.output.strip()] and res.output.startswith(line), res.output


def test_a_file_that_is_not_an_npz_is_named_as_such(tmp_path):
    """A JSON given where a volume is expected: named as not an .npz, not numpy's pickle advice."""
    from kinfu_cli.core.errors import VolumeError
    from kinfu_cli.core.volume_file import read_volume_file, read_volume_meta

    p = tmp_path / "pois.json"
    p.write_text('{"pois": []}')
    for read in (read_volume_file, read_volume_meta):
        with pytest.raises(VolumeError, match=r"not an \.npz file") as err:
            read(p)
        assert "pickle" not in str(err.value)
