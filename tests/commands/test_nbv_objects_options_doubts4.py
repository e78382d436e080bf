"""`kinfu nbv --mode objects` refuses the POI mode's viewing-sphere options (its views are 5 directions x 8 rolls
at 0.8 m around contour points, no sphere): --lon-step, --radius ... gave the same output as without them."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from tests.conftest import one_line_error


@pytest.fixture
def volume(tmp_path):
    labels = np.zeros((8, 8, 8), np.int8)
    save_ternary(tmp_path / "t.npz", TernaryGrid(labels, (0, 0, 0), 0.05))
    return tmp_path / "t.npz"


@pytest.mark.parametrize("args, flags", [
    (["--lon-step", "10"], ["--lon-step"]),
    (["--lat-step", "5", "--lat-min", "-10", "--lat-max", "80"], ["--lat-min", "--lat-max", "--lat-step"]),
    (["--roll-step", "45"], ["--roll-step"]),  # at its default value: still given, still unused
    (["--radius", "1.2", "--clear"], ["--clear", "--radius"]),
])
def test_sphere_options_with_objects_mode_are_refused(volume, tmp_path, args, flags):
    out = tmp_path / "v.json"
    res = CliRunner().invoke(cli, ["nbv", str(volume), "--mode", "objects", "-o", str(out), *args])
    line = one_line_error(res, *flags, "apply" if len(flags) > 1 else "applies", "--mode poi")
    assert line.startswith(f"kinfu: error: {', '.join(flags)}:")
    assert not out.exists()
