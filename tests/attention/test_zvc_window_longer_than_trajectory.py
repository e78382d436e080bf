"""ZVC's mean filter (2B+1 samples) longer than the trajectory: `kinfu poi REC --algorithm zvc --zvc-half-width
100000` on 495 samples gave exit 0, no POI and a warning blaming the hand's speed, "at its slowest it was nan x
that limit". Now a window longer than the whole trajectory is an error naming the option; one longer than a
single task (the others fitting) is that task's warning saying so; and no message says "nan"."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.attention.detect import detect_pois
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.trajectory import Trajectory
from tests.attention.test_hand_span import _pause_and_go
from tests.conftest import one_line_error


def test_poi_refuses_a_zvc_window_longer_than_the_trajectory(sample_dir, tmp_path):
    out = tmp_path / "z.json"
    res = CliRunner().invoke(cli, ["poi", str(sample_dir / "recording.mcap"), "--algorithm", "zvc",
                                   "--zvc-half-width", "100000", "-o", str(out), "--quiet"])
    line = one_line_error(res, "--zvc-half-width", "a mean filter of 2B+1 = 200001 samples is longer than the "
                                                   "trajectory's 495 samples; expected B at most 247")
    assert "nan" not in line and not out.exists()
    ok = CliRunner().invoke(cli, ["poi", str(sample_dir / "recording.mcap"), "--algorithm", "zvc",
                                  "--zvc-half-width", "247", "-o", str(out), "--quiet"])
    assert ok.exit_code == 0, ok.output
    assert "nan" not in ok.output


def test_the_library_names_the_parameter():
    with pytest.raises(ConfigError) as err:
        detect_pois(_pause_and_go(1.0), "zvc", {"half_width": 180})  # 361 > 360 samples
    assert err.value.parameter == "zvc_half_width" and "360 samples" in str(err.value)


def test_a_task_shorter_than_the_window_is_warned_about_without_nan():
    """A long task and a short one 5 s later (two tasks): B = 100 fits the first, not the 150-sample second."""
    first = _pause_and_go(1.0)
    rng = np.random.default_rng(1)
    short = np.linspace([0.0, 0.0, 0.0], [0.5, 0.3, 0.0], 150) + rng.normal(0, 0.001, (150, 3))  # a move
    t = np.r_[first.t, first.t[-1] + 5.0 + np.arange(150) / 100.0]
    traj = Trajectory(t=t, positions=np.r_[first.positions, short], frame="world", source="test")
    found = detect_pois(traj, "zvc", {"half_width": 100})
    assert len(found.tasks) == 2
    said = [w for w in found.document["warnings"] if "task 1:" in w]
    assert said and "2B+1 = 201 samples (zvc_half_width B = 100), more than the task's 150 samples" in said[0]
    assert not any("nan" in w for w in found.document["warnings"]), found.document["warnings"]
