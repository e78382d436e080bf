"""Bad inputs found by an adversarial campaign over every command (branch badin): each must end in one
`kinfu: error:` line (exit 2) naming the option or file, with nothing written."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.conftest import one_line_error
from tests.recordings import make_recording


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A fused volume of the tiny test recording and one POI in front of it."""
    root = tmp_path_factory.mktemp("tiny")
    rec = make_recording(root / "rec.mcap")
    res = run("fuse", rec, "-o", root / "fuse", "--resolution", "32", "--quiet")
    assert res.exit_code == 0, res.output
    (root / "pois.json").write_text(json.dumps({"pois": [{"position": [0.5, 0.0, 0.5]}]}))
    return root


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e999"])
def test_nbv_refuses_a_table_height_that_is_not_finite(tiny, tmp_path, value):
    res = run("nbv", tiny / "fuse" / "volume.npz", "--pois", tiny / "pois.json", "-o", tmp_path / "v.json",
              "--table-z", value, "--quiet")
    one_line_error(res, "--table-z", "expected")
    assert not (tmp_path / "v.json").exists()
