"""`kinfu eval localize` refuses upfront what localize refuses: a filter run estimated over its time bound
(check_run_time). It called the filter directly and ran such a run for hours."""

from __future__ import annotations

import time

import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.localization.evaluate import check_recognition, evaluate_localization
from kinfu_cli.localization.mupf import MupfParameters


def test_localization_trial_over_the_bound_is_refused_before_any_trial(tmp_path):
    start = time.perf_counter()
    res = CliRunner().invoke(cli, ["eval", "localize", "--shapes", "box", "--trials", "1", "--methods", "mupf",
                                   "--particles", "80000", "--recognition-trials", "0", "--quiet",
                                   "-o", str(tmp_path / "l.json")])
    line = one_line_error(res, "80000 particles over 15 points", "window 9", "expected at most 10 min")
    assert "particles" in line.split(":")[2]
    assert time.perf_counter() - start < 5 and not (tmp_path / "l.json").exists()


def test_recognition_over_the_bound_is_refused_before_the_localization_part():
    start = time.perf_counter()
    res = CliRunner().invoke(cli, ["eval", "localize", "--shapes", "box", "--trials", "1", "--methods",
                                   "scaling_series", "--particles", "40000", "--recognition-trials", "1", "--quiet"])
    one_line_error(res, "40000 particles over 170 points", "window 85", "x 6 models")
    assert time.perf_counter() - start < 5


def test_library_checks_alike():
    with pytest.raises(ConfigError) as err:
        evaluate_localization(["box"], trials=1, methods=["mupf"], params=MupfParameters(particles=80000))
    assert err.value.parameter == "particles"  # the protocol fixes the points and windows: max_points is not its
    check_recognition(0, 170, MupfParameters(particles=40000))  # no recognition trial: nothing to bound
    check_recognition(1, 170)


def test_the_recognition_bound_names_its_own_options():
    """The error named max_points, localize's option; eval localize's is recognition_points."""
    with pytest.raises(ConfigError) as err:
        check_recognition(1, 170, MupfParameters(particles=80000))
    assert err.value.parameter == "particles/recognition_points"
