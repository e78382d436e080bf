"""`kinfu fuse --init VOLUME` with grid options (--voxel-size, --size, --resolution, --origin): the init volume's
grid wins, as the help says, but a given value that differs from that grid was dropped without a word (exit 0,
report.json warnings []). Each now gives one warning naming the option, the value given and the grid's, on stderr
and in report.json; a value that matches the grid, or no grid option, gives none."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.recordings import make_recording


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("init")
    rec = make_recording(root / "rec.mcap")
    res = run("fuse", rec, "-o", root / "fuse", "--size", "1.6", "--resolution", "32", "--origin=-0.2,-0.8,1.0",
              "--quiet")
    assert res.exit_code == 0, res.output
    return rec, root / "fuse" / "volume.npz"


def _grid_warnings(report):
    return [w for w in report["warnings"] if "its grid wins" in w]


@pytest.mark.parametrize("option, value, said", [
    ("--voxel-size", "0.01", "--voxel-size 0.01 differs from the voxel size of the --init volume {init} (0.05 m); "
                             "its grid wins: --voxel-size is ignored"),
    ("--size", "1,1,1", "--size 1,1,1 differs from the size of the --init volume {init} (1.6,1.6,1.6 m)"),
    ("--resolution", "16", "--resolution 16 differs from the resolution of the --init volume {init} "
                           "(32,32,32 voxels)"),
    ("--origin", "0,0,0", "--origin 0,0,0 differs from the origin of the --init volume {init} (-0.2,-0.8,1 m)"),
])
def test_a_grid_option_unlike_the_init_grid_is_warned_about(base, tmp_path, option, value, said):
    rec, init = base
    res = run("fuse", rec, "-o", tmp_path / "f", "--init", init, f"{option}={value}", "--quiet")
    assert res.exit_code == 0, res.output
    said = said.format(init=init)
    report = json.loads((tmp_path / "f" / "report.json").read_text())
    warned = _grid_warnings(report)
    assert len(warned) == 1 and said in warned[0], warned
    assert f"kinfu: warning: {warned[0]}" in res.output
    assert "nan" not in warned[0]
    assert report["grid"]["voxel_size"] == pytest.approx(0.05)  # the init grid still wins
    assert np.allclose(report["grid"]["origin"], [-0.2, -0.8, 1.0])


def test_grid_options_that_match_the_init_grid_or_none_warn_nothing(base, tmp_path):
    rec, init = base
    for i, extra in enumerate(([], ["--voxel-size", "0.05", "--size", "1.6", "--origin=-0.2,-0.8,1.0"],
                               ["--resolution", "32,32,32"])):
        res = run("fuse", rec, "-o", tmp_path / f"f{i}", "--init", init, *extra, "--quiet")
        assert res.exit_code == 0, res.output
        assert _grid_warnings(json.loads((tmp_path / f"f{i}" / "report.json").read_text())) == []
        assert "its grid wins" not in res.output
