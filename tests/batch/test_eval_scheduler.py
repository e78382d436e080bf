"""`kinfu eval poi` / `kinfu eval nbv` trials on the batch engine: the same results in-process and on a 2-worker
cluster, errors raised in a trial reach the caller as the same error, and a bad scheduler is one line before
any work."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner
from conftest import one_line_error, write_hand_dataset

from kinfu_cli.batch.engine import connect
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.poi import _job_trial, find_tasks

# a tiny closed loop: 64x48 images, 3 cm voxels, a 4 x 3 x 2 viewing sphere
NBV = ["--views", "1", "--width", "64", "--height", "48", "--voxel-size", "0.03", "--scan-every", "4",
       "--lon-step", "90", "--lat-step", "45", "--roll-step", "180", "--quiet", "--json"]


@pytest.fixture(scope="module")
def hand_dataset(tmp_path_factory):
    """Four synthetic tasks (two per group) with their labelled changes."""
    return write_hand_dataset(tmp_path_factory.mktemp("hand"), seeds=range(2), noise_std=0.002)


def _run(*args) -> dict:
    res = CliRunner().invoke(cli, list(map(str, args)), catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return json.loads(res.output)


def _without_timings(doc):
    """The document without wall/CPU times (they differ between any two runs)."""
    if isinstance(doc, dict):
        return {k: _without_timings(v) for k, v in doc.items()
                if k not in ("seconds_per_task", "time_s", "seconds_per_view", "planning_seconds",
                             "planning_seconds_total", "objects_planning_s", "standard_planning_s", "time_ratio",
                             "time_ratio_standard_over_objects")}
    if isinstance(doc, list):
        return [_without_timings(v) for v in doc]
    return doc


def test_eval_poi_on_a_scheduler_gives_the_same_scores(hand_dataset, scheduler):
    args = ["eval", "poi", hand_dataset, "--speed", "1,2", "--noise", "0.01", "--json", "--quiet"]
    here = _run(*args, "--workers", "1")
    there = _run(*args, "--scheduler", scheduler)
    assert _without_timings(there) == _without_timings(here)
    # three settings x two detectors, every task scored in each, and the detectors found the changes
    assert len(here["results"]) == 6
    assert all(r["overall"]["tasks"] == 4 for r in here["results"])
    assert all(r["overall"]["recall"] >= 0.75 for r in here["results"] if r["noise"] == 0)


def test_eval_nbv_on_a_scheduler_gives_the_same_loop(sample_dir, scheduler):
    args = ["eval", "nbv", sample_dir / "ground_truth", "--strategy", "poi,random", *NBV]
    here = _run(*args)
    there = _run(*args, "--scheduler", scheduler)
    assert _without_timings(there) == _without_timings(here)
    # two trials, each took its views and revealed part of its POI spheres, from the same cleared volume
    assert set(here["strategies"]) == {"poi", "random"}
    first = str(here["pois"][0]["id"])
    for r in here["strategies"].values():
        assert r["final_unknown"] < r["initial_unknown"] and r["frames_fused"] >= 3
    assert here["strategies"]["poi"]["unknown"][first][0] == here["strategies"]["random"]["unknown"][first][0]


@pytest.mark.slow
def test_eval_nbv_exploration_on_a_scheduler_gives_the_same_runs(sample_dir, scheduler):
    args = ["eval", "nbv", sample_dir / "ground_truth", "--strategy", "objects,standard", "--views", "1",
            "--width", "64", "--height", "48", "--voxel-size", "0.03", "--score-width", "32", "--quiet", "--json"]
    here = _run(*args)
    there = _run(*args, "--scheduler", scheduler)
    assert _without_timings(there) == _without_timings(here)
    # the whole-scene strategy took its view and revealed unknown space near the objects
    st = here["strategies"]["standard"]
    assert st["views_taken"] == 1 and st["unknown_near"][1] < st["unknown_near"][0]


def test_a_trial_error_reaches_the_caller_with_its_parameter(hand_dataset, scheduler):
    task = find_tasks(hand_dataset)[0]
    engine = connect(scheduler)
    try:
        good = engine.map_trials(_job_trial, [(task, 1.0, 0.0, 0, ["zvc"], {})], quiet=True)
        assert good[0][0]["task"] == task.name and good[0][0]["changes"] >= 1
        with pytest.raises(ConfigError) as err:
            engine.map_trials(_job_trial, [(task, 1.0, 0.0, 0, ["zvc"], {}), (task, -1.0, 0.0, 0, ["zvc"], {})],
                              quiet=True)
        assert err.value.parameter == "speed" and ">= 0.01" in str(err.value)
    finally:
        engine.close()


def test_bad_scheduler_is_one_line_before_any_work(hand_dataset, sample_dir, tmp_path, quick_refusal):
    out = tmp_path / "loop.json"
    nbv = ["eval", "nbv", str(sample_dir / "ground_truth"), "-o", str(out), *NBV]
    runner = CliRunner()
    one_line_error(runner.invoke(cli, [*nbv, "--scheduler", "tcp://127.0.0.1:9"]), "--scheduler", "cannot reach")
    one_line_error(runner.invoke(cli, [*nbv, "--scheduler", "localhost"]), "--scheduler", "tcp://host")
    one_line_error(runner.invoke(cli, [*nbv, "--scheduler", "tcp://127.0.0.1:9", "--workers", "2"]), "--workers",
                   "--scheduler")
    one_line_error(runner.invoke(cli, [*nbv, "--scheduler", "tcp://127.0.0.1:9", "--views", "0"]), "--views")
    assert not out.exists()
    poi = ["eval", "poi", str(hand_dataset), "--quiet"]
    one_line_error(runner.invoke(cli, [*poi, "--scheduler", "tcp://127.0.0.1:9"]), "--scheduler", "cannot reach")
    one_line_error(runner.invoke(cli, [*poi, "--scheduler", "tcp://127.0.0.1:9", "--workers", "2"]), "--workers")


def test_workers_start_a_local_cluster_and_neither_runs_in_process(hand_dataset):
    from kinfu_cli.commands._engine import trial_engine

    job = (find_tasks(hand_dataset)[0], 1.0, 0.0, 0, ["zvc"], {})
    with trial_engine(None, None, desc="t", quiet=True) as tmap:
        assert tmap is None  # in-process: the driver's own path, unchanged
    with trial_engine(None, 1, desc="t", quiet=True) as tmap:
        (rows,) = tmap(_job_trial, [job])
    assert rows == [{**r, "seconds": rows[0]["seconds"], "cpu_seconds": rows[0]["cpu_seconds"]}
                    for r in _job_trial(None, job)]
