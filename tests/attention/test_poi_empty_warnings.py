"""`kinfu poi` says why a result is empty, or made of noise, instead of writing it silently.

Before: a hand that never moved gave "0 POI(s) ... K = 1 Gaussians" (GMM-AS) or one POI of saliency 0.003 (ZVC,
tracker jitter), and a hand moving only up and down 0 POIs from ZVC, all with `warnings: []`; `kinfu nbv` then
refuses the empty pois.json.
"""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.attention.detect import HAND_STILL_M, detect_pois
from kinfu_cli.cli import cli
from kinfu_cli.io.polhemus import write_polhemus
from kinfu_cli.io.trajectory import Trajectory


def _traj(p) -> Trajectory:
    return Trajectory(t=np.arange(len(p)) / 100.0, positions=np.asarray(p, float), frame="world", source="test")


def _still(n=300, jitter=0.0005) -> np.ndarray:
    return np.tile([0.1, 0.1, 0.8], (n, 1)) + np.random.default_rng(0).normal(0, jitter, (n, 3))


@pytest.mark.parametrize("algorithm", ["gmm-as", "zvc"])
def test_a_hand_that_never_moved_is_said_whatever_the_detector_found(algorithm):
    found = detect_pois(_traj(_still()), algorithm)
    (w,) = found.document["warnings"]
    assert w.startswith("the hand stays within") and "it never moved" in w
    span_cm = float(w.split("within ")[1].split(" cm")[0])
    assert span_cm < 100 * HAND_STILL_M
    n = len(found.pois)
    assert (f"its {n} POI(s) come from tracker jitter" if n else "no POI can be found") in w


def test_a_single_move_is_too_few_gaussians_for_gmm_as():
    line = np.linspace([0, 0, 0], [0.6, 0, 0], 300) + np.random.default_rng(0).normal(0, 0.001, (300, 3))
    found = detect_pois(_traj(line), "gmm-as")
    assert found.pois == [] and found.detectors[0].n_components_ < 3
    (w,) = found.document["warnings"]
    assert w.startswith(f"GMM-AS fitted K = {found.detectors[0].n_components_} Gaussian(s)")
    assert "a POI is a Gaussian between two others" in w


@pytest.mark.parametrize("algorithm, says", [("gmm-as", "no GMM-AS Gaussian is more salient than POITh = 1.5"),
                                              ("zvc", "never fell below ZVC's slow limit (relative rule)")])
def test_a_hand_that_never_dwells_gets_an_empty_result_warning(algorithm, says):
    th = np.linspace(0, 2 * np.pi, 300)  # a circle at constant speed: moving, never slowing down
    circle = np.c_[0.3 * np.cos(th), 0.3 * np.sin(th), np.zeros(300)] + np.random.default_rng(0).normal(0, 0.001,
                                                                                                        (300, 3))
    found = detect_pois(_traj(circle), algorithm)
    assert found.pois == []
    (w,) = found.document["warnings"]
    assert w.startswith("no POI found: ") and says in w
    closest = float(w.split("reached " if algorithm == "gmm-as" else "slowest it was ")[1].split(" x")[0])
    assert (closest < 1.0) if algorithm == "gmm-as" else (closest > 1.0)


def test_only_the_still_task_of_several_is_named():
    moving = np.concatenate([np.zeros((100, 3)), np.linspace([0, 0, 0], [0.6, 0, 0], 60),
                             np.tile([0.6, 0, 0], (100, 1))])
    moving += np.random.default_rng(1).normal(0, 0.001, moving.shape)
    p = np.concatenate([moving, _still()])
    t = np.r_[np.arange(len(moving)), np.arange(300) + len(moving) + 500] / 100.0  # a 5 s pause: two tasks
    found = detect_pois(Trajectory(t=t, positions=p, frame="world", source="test"), "zvc")
    assert len(found.tasks) == 2
    (w,) = found.document["warnings"]
    assert w.startswith("task 1: the hand stays within")


def test_kinfu_poi_prints_the_warning_and_writes_it(tmp_path):
    traj = write_polhemus(tmp_path / "still.traj", _traj(_still()))
    out = tmp_path / "pois.json"
    res = CliRunner().invoke(cli, ["poi", str(traj), "-o", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: the hand stays within" in res.output and "Traceback" not in res.output
    assert any("it never moved" in w for w in json.loads(out.read_text())["warnings"])


def test_a_kmax_under_three_is_refused_up_front():
    """--max-components 1 or 2 ran and warned that the trajectory held no dwell: the option itself can never give a
    POI (one is a Gaussian between two others), so it is refused naming the parameter."""
    import pytest

    from kinfu_cli.attention.gmm_as import GmmActivitySaliency
    from kinfu_cli.core.errors import ConfigError

    for k in (1, 2):
        with pytest.raises(ConfigError, match="expected at least 3: a POI is a Gaussian between two others") as e:
            GmmActivitySaliency(max_components=k).check_params()
        assert e.value.parameter == "max_components"
    GmmActivitySaliency(max_components=3).check_params()
