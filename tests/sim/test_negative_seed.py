"""A negative seed is a ConfigError naming `seed` (numpy's default_rng refuses it with a bare ValueError, which
reached the user as a traceback from `kinfu synth / eval grasp / eval localize --seed -1`, `eval segment --sweep --scenes=-1`)."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.poi import evaluate_dataset
from kinfu_cli.evaluation.segment_eval import sweep_segmentation
from kinfu_cli.grasp.evaluate import evaluate_grasping
from kinfu_cli.localization import shapes
from kinfu_cli.localization.evaluate import evaluate_localization, evaluate_recognition
from kinfu_cli.localization.localize import localize_points
from kinfu_cli.sim.synth import synthesize


@pytest.mark.parametrize("call, parameter", [
    (lambda tmp: synthesize(tmp / "out", seed=-1, frames=3, quiet=True), "seed"),
    (lambda tmp: evaluate_grasping(seed=-1), "seed"),
    (lambda tmp: evaluate_grasping(scenes=(0, -2)), "scenes"),
    (lambda tmp: sweep_segmentation(seeds=(-1,)), "scenes"),
    (lambda tmp: evaluate_dataset(tmp, ["zvc"], noises=[0.01], seed=-5), "seed"),
    (lambda tmp: evaluate_localization(trials=1, seed=-1), "seed"),
    (lambda tmp: evaluate_recognition(seed=-1), "seed"),
    (lambda tmp: localize_points([shapes.box()], np.random.default_rng(0).normal(size=(50, 3)) * 0.02, seed=-3),
     "seed"),
])
def test_a_negative_seed_is_a_config_error(tmp_path, call, parameter):
    with pytest.raises(ConfigError) as err:
        call(tmp_path)
    assert err.value.parameter == parameter
    assert not (tmp_path / "out").exists()
