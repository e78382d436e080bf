"""Option values a fuzz pass over the command lines found (session 23): extreme numbers that passed a "positive"
check and then overflowed or divided by zero (tracebacks), a numpy warning before the error line, Infinity written
into pois.json, and the bare groups' help squeezed into an error line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.commands.diff import change_params
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.reconstruction import _sampled_spacing
from kinfu_cli.localization.mupf import MupfParameters
from kinfu_cli.sim.sampling import sample_surface


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.mark.parametrize("value", ["1e-300", "1e308", "nan"])
def test_fuse_max_memory_out_of_range_is_one_line(sample_dir, tmp_path, value):
    res = _run("fuse", sample_dir / "recording.mcap", "-o", tmp_path / "f", "--every", 3, "--quiet",
               "--max-memory", value)
    one_line_error(res, "--max-memory: expected a number of GiB from 0.001 to 1e+06")
    assert not (tmp_path / "f").exists()


def test_fuse_size_of_1e308_is_one_line_without_a_numpy_warning(sample_dir, tmp_path):
    res = _run("fuse", sample_dir / "recording.mcap", "-o", tmp_path / "f", "--quiet", "--resolution", 64,
               "--size", "1e308")
    one_line_error(res, "--size: expected positive lengths in metres up to 1e+06")  # one line: no RuntimeWarning


@pytest.mark.parametrize("args, needle", [
    (["--frame-rate", "1e-300"], "--frame-rate: expected a finite number >= 0.01 and <= 1000 Hz"),
    (["--frame-rate", "0"], "--frame-rate: expected a finite number >= 0.01"),
    (["--hand-rate", "1e-300"], "--hand-rate: expected a finite number >= 1 and <= 10000 Hz"),
])
def test_synth_rates_too_low_are_one_line(tmp_path, args, needle):
    res = _run("synth", "-o", tmp_path / "s", "--width", 32, "--height", 24, "--frames", 3, "--formats", "mcap",
               "--quiet", *args)
    one_line_error(res, needle)
    assert not (tmp_path / "s").exists()


def test_eval_poi_speed_out_of_range_is_one_line(tmp_path):
    for speed in ("1e-300", "0.5,200"):
        one_line_error(_run("eval", "poi", tmp_path, "--quiet", "--speed", speed),
                       "--speed: expected a finite number >= 0.01 and <= 100")


def test_poi_split_gap_inf_is_refused_not_written_as_infinity(sample_dir, tmp_path):
    out = tmp_path / "pois.json"
    one_line_error(_run("poi", sample_dir / "recording.mcap", "-o", out, "--quiet", "--split-gap", "inf"),
                   "--split-gap: expected finite seconds >= 0")
    assert not out.exists()


@pytest.mark.parametrize("radius", [float("inf"), 1e308, 0.0, float("nan")])
def test_diff_match_radius_is_a_finite_distance(radius):
    with pytest.raises(ConfigError, match=r"^match_radius: expected a finite number > 0 and <= 1e\+06 m"):
        change_params({"match_radius": radius, "margin": 1, "min_volume": 2e-6, "noise_sigmas": 3.0})


@pytest.mark.parametrize("field, value", [("noise", 1e308), ("sigma_p2", float("inf")), ("max_index", 1e308)])
def test_localize_distances_beyond_the_data_bound_are_refused(field, value):
    with pytest.raises(ConfigError, match=rf"^{field}: expected a finite number > 0 and <= 1e\+"):
        MupfParameters(**{field: value}).check()


def test_a_sample_spacing_that_squares_to_zero_is_capped_with_a_warning():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    f = np.array([[0, 1, 2]])
    pts, _ = sample_surface(v, f, 1e-300, max_samples=50)
    assert len(pts) == 50
    used, warnings = _sampled_spacing(0.5, 50, 1e-300, "after")
    assert used == pytest.approx(0.1) and "more than the sampler's" in warnings[0]


@pytest.mark.parametrize("group", [[], ["eval"]])
def test_a_group_without_its_command_prints_its_help(group):
    res = CliRunner().invoke(cli, group, prog_name="kinfu")
    assert res.exit_code == 0
    assert res.output.startswith(f"Usage: kinfu {' '.join(group)}".rstrip() + " [OPTIONS] COMMAND")
    assert "Commands:" in res.output and "kinfu: error" not in res.output


def test_every_json_number_written_by_poi_is_finite(sample_dir, tmp_path):
    out = tmp_path / "pois.json"
    res = _run("poi", sample_dir / "recording.mcap", "-o", out, "--quiet", "--split-gap", "0")
    assert res.exit_code == 0, res.output
    json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"{c} in pois.json"))


def test_eval_poi_zvc_window_longer_than_a_path_is_one_line_not_a_silent_zero(tmp_path):
    from conftest import write_hand_dataset

    data = write_hand_dataset(tmp_path / "hands", seeds=[0])
    res = _run("eval", "poi", data, "--algorithm", "zvc", "--zvc-half-width", 100000, "--workers", 1, "--quiet")
    line = one_line_error(res, "--zvc-half-width: a mean filter of 2B+1 = 200001 samples is longer than the "
                               "trajectory's")
    assert "user9_obj0.traj, speed 1)" in line
    ok = _run("eval", "poi", data, "--algorithm", "zvc", "--workers", 1, "--quiet", "--json")
    assert ok.exit_code == 0, ok.output
