"""`kinfu localize` refuses at once a run whose filtering is estimated to take over MAX_SECONDS (time grows with
particles x points x window and with particles^2: 100,000 particles or all 12,000 points of a cloud ran for hours),
naming the options that drive it and the estimated time."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.localization.localize import MAX_SECONDS, check_run_time, localize_points
from kinfu_cli.localization.mesh_model import MeshModel
from kinfu_cli.localization.mupf import MupfParameters, estimated_seconds, window_points
from tests.localization.test_localize_cli import V, F, _points, _write_mesh


def test_too_many_particles_are_refused_with_the_estimated_time(tmp_path):
    mesh = _write_mesh(tmp_path / "model.ply")
    txt = tmp_path / "touches.txt"
    np.savetxt(txt, _points(20))
    res = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "--particles", "100000", "--quiet",
                                   "-o", str(tmp_path / "pose.json")])
    line = one_line_error(res, "--particles/--max-points/--window", "100000 particles over 20 points",
                          "min of filtering", "expected at most 10 min")
    assert "window 10 (half the points)" in line
    assert not (tmp_path / "pose.json").exists()


def test_all_points_of_a_large_cloud_are_refused_naming_how_many(tmp_path):
    mesh = _write_mesh(tmp_path / "model.ply")
    txt = tmp_path / "cloud.txt"
    np.savetxt(txt, _points(12_000))
    res = CliRunner().invoke(cli, ["localize", str(mesh), str(txt), "--max-points", "0", "--quiet"])
    line = one_line_error(res, "--max-points", "700 particles over 12000 points", "window 6000")
    assert f"about {estimated_seconds(MupfParameters(), 12_000) / 60:.0f} min of filtering" in line  # ~48 min
    assert "--max-points" in CliRunner().invoke(cli, ["localize", "--help"]).output


def test_the_estimate_grows_with_particles_points_and_models():
    p = MupfParameters()
    assert window_points(10, None) == sum(min(k, 5) for k in range(1, 11))
    assert window_points(10, 3) == sum(min(k, 3) for k in range(1, 11))
    assert estimated_seconds(p, 100) < 5  # the defaults: under 1 s measured
    assert estimated_seconds(p, 2000) / estimated_seconds(p, 1000) > 3  # ~L^2 through the window
    assert check_run_time(p, 100, 3) == pytest.approx(3 * estimated_seconds(p, 100))
    with pytest.raises(ConfigError) as err:
        check_run_time(p, 4000, 2, n_given=9000)
    assert "4000 points (of 9000)" in str(err.value) and "x 2 models" in str(err.value)
    assert err.value.parameter == "particles/max_points/window"
    assert 2 * estimated_seconds(p, 4000) > MAX_SECONDS > estimated_seconds(p, 4000)


def test_a_run_within_the_bound_still_runs():
    pts = _points(20)
    res = localize_points([MeshModel(V - V.mean(0), F)], pts, MupfParameters(particles=60), prior="zero")
    assert res.n_points == 20
