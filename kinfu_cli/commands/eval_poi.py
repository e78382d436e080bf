"""`kinfu eval poi`: GMM-AS and ZVC against hand-labelled changes, the paper's Tables 2-4 side by side."""

from __future__ import annotations

import math
import os
from pathlib import Path

import click

from kinfu_cli.commands._engine import scheduler_option, trial_engine
from kinfu_cli.commands._options import Inapplicable, check_inapplicable, comma_values, result_options
from kinfu_cli.commands._detector_options import (DETECTOR_OPTIONS, detector_inapplicable, detector_options,
                                                  detector_params_from)
from kinfu_cli.commands._output import QUIET_HELP, emit
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.poi import (MAX_SPEED, MIN_SPEED, evaluate_dataset, format_sample, format_tables,
                                      sample_statement)

group = "eval"


def _floats(option: str, value: str | None, blank_ok: bool = True) -> list[float]:
    """The numbers of a comma-separated option; blank: [] (--noise '': none) unless not blank_ok (--speed)."""
    if value is None or (blank_ok and not value.strip()):
        return []
    try:
        values = [float(v) for v in comma_values(value, option)]
    except ValueError:
        values = [math.nan]
    if not all(math.isfinite(v) for v in values):  # nan / inf were taken as a setting and scored
        raise ConfigError(f"{option}: expected comma-separated finite numbers, got {value!r}")
    return values


# --loo chooses the constants itself, on the recorded tasks: the detector options and the speed / noise settings
# have no effect there; without it, those of the detector not scored
INAPPLICABLE = (
    Inapplicable(("speed", "noise", "seed", *(n.replace("_", "-") for n in DETECTOR_OPTIONS)),
                 lambda p: "with --loo" if p["loo"] else None,
                 "to the scoring of the given settings (--loo chooses each constant itself, on the recorded tasks)"),
    *detector_inapplicable(lambda p: {"gmm-as", "zvc"} if p["algorithm"] == "both" else {p["algorithm"]}),
)


@click.command("poi", short_help="Score GMM-AS / ZVC POIs on a hand data set (paper Tables 2-4).")
@click.argument("dataset_dir", type=click.Path(path_type=Path))
@click.option("--algorithm", default="both", show_default=True, type=click.Choice(["gmm-as", "zvc", "both"]),
              help="Detector(s) to score.")
@click.option("--speed", "speed", default="1", show_default=True,
              help="Comma-separated speed multipliers (Table 3), e.g. 0.25,0.5,1,2,4.")
@click.option("--noise", "noise", default="", help="Comma-separated noise std in metres (Table 4), e.g. 0.001,0.025,0.05.")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the added noise.")
@click.option("--workers", default=None, type=click.IntRange(min=1),
              help="Processes [default: number of CPUs, at most 8].")
@scheduler_option
@click.option("--loo", is_flag=True,
              help="Leave-one-user-out instead: choose each default constant on one user, score it on another "
                   "(kinfu_cli/evaluation/poi_loo.py); the detector, --speed, --noise and --seed options do not "
                   "apply.")
@result_options(output=None, json="Print machine-readable results on stdout.", quiet=QUIET_HELP, force=False)
@detector_options
def command(dataset_dir, algorithm, speed, noise, seed, workers, scheduler, loo, as_json, quiet, **kw):
    """Run GMM-AS and/or ZVC on every *.traj with a *.traj.res beside it and score them.

    Tasks are grouped by sub-folder (placements_removals, pick_and_place). A POI within 0.20 m of a
    labelled change is a true positive, else a false positive; a change with no POI within 0.20 m is
    a false negative (RAS 2016 Sec. 6.2). Speed multipliers re-time and resample each trajectory;
    noise is white Gaussian on the positions with a fixed seed. Prints the paper's Tables 2, 3 and 4
    with the paper's numbers beside ours.

    --json prints, for a single (algorithm, speed, noise) setting, one object
    {"algorithm", "speed", "noise", "groups": {"<subfolder>": {"precision", "recall", "tp", "fp", "fn",
    "changes", "tasks"}}, "overall": {...}, "seconds_per_task": {"median", "max", "cpu_median", "cpu_max"}};
    for several
    settings, {"results": [one such object per setting]} (Table 3 rows, then Table 4 rows, per
    algorithm). Both carry "sample": {"users_scored": {user: tasks}, "defaults_chosen_on": [users],
    "in_sample": [...], "out_of_sample": [...]} (the defaults were chosen on users 1 and 4: their
    scores are in-sample), also printed under the tables.

    --scheduler runs the (task, setting) trials as tasks on a running dask.distributed cluster (the engine of
    `kinfu batch`) instead of local processes; the results are the same.

    --loo chooses each default constant on one user and scores it on the other (every ordered pair of
    users in DATASET_DIR), on the recorded tasks and with their pauses shortened; --json prints that
    document instead.

    \b
    Example:
      kinfu eval poi ../shared/data/hand-polhemus
      kinfu eval poi DATA --algorithm gmm-as --speed 0.25,0.5,1,2,4 --noise 0.001,0.025,0.05 --workers 2
      kinfu eval poi DATA --algorithm zvc --json
      kinfu eval poi DATA --loo --workers 2
      kinfu eval poi DATA --speed 0.25,0.5,1,2,4 --scheduler tcp://10.0.0.5:8786
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    speeds = _floats("--speed", speed, blank_ok=False)
    noises = _floats("--noise", noise)
    for s in speeds:
        check_number(s, "speed", MIN_SPEED, MAX_SPEED)
    if any(n < 0 for n in noises):
        raise ConfigError(f"--noise: expected standard deviations >= 0 metres, got {noise!r}")
    params = detector_params_from(kw)
    algorithms = ["gmm-as", "zvc"] if algorithm == "both" else [algorithm]
    with trial_engine(scheduler, workers if scheduler is not None else None, desc="eval poi", quiet=quiet) as tmap:
        if workers is None:
            workers = max(1, min(8, os.cpu_count() or 1))
        if loo:
            from kinfu_cli.evaluation.poi_loo import format_loo, leave_one_user_out
            doc = leave_one_user_out(dataset_dir, algorithms, workers=workers, quiet=quiet, map_trials=tmap)
            emit(doc, None, as_json, lambda d: [format_loo(d)], quiet)
            return
        results, rows = evaluate_dataset(dataset_dir, algorithms, speeds, noises, workers=workers, params=params,
                                          seed=seed, quiet=quiet, map_trials=tmap)
    sample = sample_statement(rows)
    doc = dict(results[0]) if len(results) == 1 else {"results": results}
    doc["sample"] = sample
    emit(doc, None, as_json, lambda d: [format_tables(results), format_sample(sample)], quiet)
