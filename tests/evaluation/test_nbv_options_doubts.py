"""`kinfu eval nbv` refuses what it would silently not do: a --strategy list that splits to nothing (it ran no
strategy and exited 0) and a --poi it does not use (a kinfu synth folder brings its own POIs; the objects /
standard exploration takes none), which was recorded in the result as if it had been looked at. On a bare mesh,
for poi / random / fixed, --poi is the POI."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.nbv_loop import LoopConfig, load_scene


@pytest.mark.parametrize("strategies, said", [
    (",", "an empty item; expected comma-separated values without gaps"),
    (" , ,", "an empty item; expected comma-separated values without gaps"),
    ("", "expected a value, got an empty one")])
def test_empty_strategy_list_is_an_error(sample_dir, tmp_path, strategies, said):
    """The shared comma-list parsing (commands/_options.comma_values) refuses these before LoopConfig sees them."""
    out = tmp_path / "nbv.json"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(sample_dir), "--strategy", strategies, "--quiet",
                                   "-o", str(out)])
    one_line_error(res, "--strategy", said)
    assert not out.exists()


def test_empty_strategies_fail_the_check():
    with pytest.raises(ConfigError, match="poi, random, fixed, objects, standard") as info:
        LoopConfig(strategies=()).check()
    assert info.value.parameter == "strategies"


@pytest.mark.parametrize("strategy, detail", [("poi,random", "brings its POIs"),
                                              ("objects", "POI-free exploration (objects) takes no POI")])
def test_poi_on_a_synth_folder_is_refused(sample_dir, tmp_path, strategy, detail):
    out = tmp_path / "nbv.json"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(sample_dir), "--strategy", strategy, "--poi", "0", "0", "0.8",
                                   "--quiet", "-o", str(out)])
    one_line_error(res, "--poi", detail)
    assert not out.exists()


def test_poi_on_a_bare_mesh_is_the_poi(sample_dir):
    sc = load_scene(sample_dir / "ground_truth" / "scene_after.ply", LoopConfig(poi=(0.36, -0.15, 0.8)))
    assert np.allclose(sc.changes, [[0.36, -0.15, 0.8]])
