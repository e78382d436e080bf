"""`kinfu eval nbv`: the paper's Algorithm 1 in simulation (POI views vs random views vs a fixed scan)."""

from __future__ import annotations

from pathlib import Path

import click

from kinfu_cli.commands._engine import scheduler_option, trial_engine
from kinfu_cli.commands._options import Inapplicable, check_inapplicable, claim_outputs, comma_values, result_options
from kinfu_cli.commands._output import QUIET_HELP, emit
from kinfu_cli.core.pois import DEFAULT_RADIUS
from kinfu_cli.evaluation.nbv_loop import EXPLORE, LoopConfig, run_loop
from kinfu_cli.evaluation.tables import nbv_loop_table
from kinfu_cli.nbv.gains import gain_names
from kinfu_cli.nbv.viewpoints import PAPER_SPHERE, sphere_viewpoints
from kinfu_cli.report.eval_nbv_plot import plot_nbv_loop

group = "eval"


def _strategies(p: dict, explore: bool) -> str | None:
    """'with --strategy S' when every strategy given is of the exploration (explore) or of the POI loop (not
    explore); None otherwise (a list with a gap, or mixed: their own errors)."""
    items = [s.strip() for s in p["strategies"].split(",")]
    if not all(items) or not all((s in EXPLORE) == explore for s in items):
        return None
    return f"with --strategy {','.join(items)}"


# options given where they do nothing (commands._options.check_inapplicable); --poi and --pois-from with the
# exploration are LoopConfig's own errors
INAPPLICABLE = (
    Inapplicable(("scan-frames", "near-margin", "score-width"), lambda p: _strategies(p, False),
                 "to the POI-free exploration (--strategy objects,standard)"),
    Inapplicable(("mode", "inc-th", "poi-radius", "lon-step", "lat-step", "roll-step"), lambda p: _strategies(p, True),
                 "to the POI loop (--strategy poi, random, fixed; the exploration fuses at its views, plans from "
                 "contours and stops on its own score)"),
)


def loop_config(p: dict) -> LoopConfig:
    """The checked LoopConfig from the command's parsed options (click's parameter dict): the one place that turns
    eval nbv's options into it, for the command and for `check_options`."""
    modes = ("kfovp", "kfom") if p["mode"] == "both" else (p["mode"],)
    cfg = LoopConfig(strategies=tuple(comma_values(p["strategies"], "--strategy")), modes=modes,
                     views=p["views"], voxel_size=p["voxel_size"], gain=p["gain"], inc_th=p["inc_th"],
                     poi_radius=p["poi_radius"], pois_from=p["pois_from"], oscillation_deg=p["oscillation"],
                     scan_every=p["scan_every"], width=p["width"], height=p["height"], noise=not p["no_noise"],
                     seed=p["seed"], optimistic=p["optimistic"],
                     sphere=dict(lon_step=p["lon_step"], lat_step=p["lat_step"], roll_step=p["roll_step"]),
                     poi=tuple(p["poi"]) if p["poi"] else None, scan_frames=p["scan_frames"],
                     near_margin=p["near_margin"], score_width=p["score_width"], reject_unknown=p["reject_unknown"])
    cfg.check()
    return cfg


def check_options(params: dict) -> None:
    """What `kinfu eval nbv` refuses with these options before it reads the scene (kinfu batch checks a plan with
    it); ConfigError naming the parameter."""
    cfg = loop_config(params)
    if not set(cfg.strategies) <= set(EXPLORE):  # the POI strategies rank the viewing sphere of its steps
        sphere_viewpoints((0.0, 0.0, 0.0), **cfg.sphere)


@click.command("nbv", short_help="Closed NBV loop in simulation: POI views vs random/fixed, objects vs standard.")
@click.argument("scene", type=click.Path(path_type=Path))
@click.option("--strategy", "strategies", default="poi,random,fixed", show_default=True,
              help="Comma-separated strategies: poi (Alg. 1 NBV), random, fixed (ring at 40 deg latitude); or "
                   "the POI-free whole-scene exploration: objects (most salient segment first, thesis Alg. 4), "
                   "standard (every contour view scored on the whole volume).")
@click.option("--views", default=5, show_default=True, type=int, help="View budget per POI.")
@click.option("--mode", default="kfovp", show_default=True, type=click.Choice(["kfovp", "kfom", "both"]),
              help="KFOVP: fuse at views only; KFOM: also along the straight path between views.")
@click.option("--voxel-size", default=0.01, show_default=True, type=float,
              help="Simulation volume voxel (m); coarser than the 512^3 KinFu grid so the loop is quick.")
@click.option("--gain", default="unknown", show_default=True,
              type=click.Choice(list(gain_names())), help="Gain function.")
@click.option("--inc-th", type=float, default=None, help="IncTh [default: 1% of the pixels that see S(POI)].")
@click.option("--poi-radius", default=DEFAULT_RADIUS, show_default=True, type=float, help="Radius of S(POI) (m).")
@click.option("--pois-from", default=None, type=click.Choice(["gmm-as", "truth"]),
              help="POIs of a kinfu synth folder SCENE from GMM-AS on the simulated hand trajectory, or the true "
                   "changes (poi, random, fixed; a bare mesh takes --poi). A folder without hand.traj has only the "
                   "true changes: by default they are taken with a warning, gmm-as is refused.  [default: gmm-as]")
@click.option("--poi", nargs=3, type=float, default=None,
              help="POI x y z for a bare mesh SCENE (poi, random, fixed; a kinfu synth folder brings its own).")
@click.option("--optimistic/--paper-stop", default=True, show_default=True,
              help="Unknown voxels outside S(POI) do not stop rays (the initial scan leaves the space around "
                   "the table unseen) / stop them as in the paper.")
@click.option("--oscillation", default=5.0, show_default=True, type=float,
              help="Tilt +- this many degrees at each view (extra frames; also widens the NBV vertical FOV).")
@click.option("--width", type=int, default=None, help="Sensor image width [scene camera].")
@click.option("--height", type=int, default=None, help="Sensor image height [scene camera].")
@click.option("--scan-every", default=1, show_default=True, type=int, help="Use every k-th initial-scan pose.")
@click.option("--lon-step", default=PAPER_SPHERE.lon_step, show_default=True, type=float, help="Viewing sphere longitude step (deg).")
@click.option("--lat-step", default=PAPER_SPHERE.lat_step, show_default=True, type=float, help="Viewing sphere latitude step (deg).")
@click.option("--roll-step", default=PAPER_SPHERE.roll_step, show_default=True, type=float, help="Viewing sphere roll step (deg).")
@click.option("--scan-frames", default=8, show_default=True, type=int,
              help="objects/standard: initial scan = the first N scan poses (one side of the table).")
@click.option("--near-margin", default=0.2, show_default=True, type=float,
              help="objects/standard: 'near objects' = inside a true object's bounding sphere + this (m).")
@click.option("--score-width", default=80, show_default=True, type=int,
              help="objects/standard: width of the image views are scored with (same field of view).")
@click.option("--reject-unknown", is_flag=True,
              help="Candidate views with the sensor in unknown space score 0 (the paper's robot); default: allowed.")
@click.option("--no-noise", is_flag=True, help="Render exact depth (no Kinect noise model).")
@click.option("--seed", default=0, show_default=True, type=int, help="Noise and random-strategy seed.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Run the strategy trials on a local Dask cluster of this many processes [in this process].")
@scheduler_option
@result_options(output="Write the result JSON here.", json="Print the result JSON on stdout.",
                quiet=QUIET_HELP,
                plot="PNG: unknown voxels in each POI sphere vs views (the paper's Fig. 20).", dir_okay=True)
def command(scene, strategies, views, mode, voxel_size, gain, inc_th, poi_radius, pois_from, poi, optimistic,
            oscillation, width, height, scan_every, lon_step, lat_step, roll_step, scan_frames, near_margin,
            score_width, reject_unknown, no_noise, seed, output, plot, workers, scheduler, quiet, as_json, force):
    """Run the paper's Algorithm 1 on a simulated scene and compare view strategies.

    SCENE is a `kinfu synth` ground_truth folder (or the recording folder holding it) or a mesh file
    (then give --poi). Initial scan of the scene before the change, the change, POIs from the hand
    trajectory (GMM-AS), ForgetAround, then per POI: rank, move, oscillate, fuse, re-rank until the
    best gain drops below IncTh or the view budget is spent. Reports unknown voxels in each POI
    sphere after each view, views until IncTh, the final reconstruction error against the true
    after-change mesh and the time per stage, for each strategy.

    With --strategy objects,standard (POI-free exploration, thesis ch. 3): from a short initial scan of
    the scene, each strategy takes up to --views views; reported per strategy: unknown voxels near the
    true objects after each view, candidate views ray-cast and planning time, and how many candidates
    each needed for the same reduction.

    --workers N / --scheduler tcp://HOST:PORT run each (strategy, mode) trial as a task on a local Dask
    cluster / a running dask.distributed cluster (the engine of `kinfu batch`); the results are the same.

    \b
    Example:
      kinfu eval nbv sample_data/tabletop/ground_truth --views 4 --plot out/nbv_loop.png
      kinfu eval nbv sample_data/tabletop --strategy poi,random --mode both --voxel-size 0.015 --json
      kinfu eval nbv sample_data/tabletop --strategy objects,standard --width 160 --height 120
      kinfu eval nbv sample_data/tabletop --strategy poi,random,fixed --mode both --workers 2
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    claim_outputs({"output": output, "plot": plot}, [scene], force)
    cfg = loop_config(click.get_current_context().params)  # bad values fail before connecting to a cluster
    with trial_engine(scheduler, workers, desc="eval nbv", quiet=quiet) as tmap:
        doc = run_loop(scene, cfg, quiet=quiet, map_trials=tmap)
    if plot is not None:
        plot_nbv_loop(plot, doc)
        doc["plot"] = str(plot)
    emit(doc, output, as_json, nbv_loop_table, quiet)
