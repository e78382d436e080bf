"""`kinfu poi`: points of interest (where the person acted) from the hand trajectory, GMM-AS or ZVC."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinfu_cli.core.errors import ConfigError


def _time_scale(value: str) -> str | float:
    if value.strip().lower() == "duration":
        return "duration"
    try:
        return float(value)
    except ValueError:
        raise ConfigError(f"--time-scale: expected 'duration' or units per second, got {value!r}") from None


def detector_options(f):
    """The GMM-AS and ZVC parameters as options (shared by `kinfu poi` and `kinfu eval poi`)."""
    opts = [
        click.option("--poi-threshold", default=1.5, show_default=True, type=float,
                     help="GMM-AS POITh: saliency must exceed this x the neighbours' mean (paper Table 2: 2.5; "
                          "Tables 5-6: 1.5)."),
        click.option("--neighbours", default=2, show_default=True, type=int, help="GMM-AS Lambda: neighbours each side."),
        click.option("--bic-threshold", default=0.0, show_default=True, type=float,
                     help="GMM-AS BICTh: stop when BIC > min BIC + this."),
        click.option("--max-components", default=15, show_default=True, type=int, help="GMM-AS Kmax."),
        click.option("--selection", default="first-minimum", show_default=True,
                     type=click.Choice(["first-minimum", "best"]), help="GMM-AS: first BIC minimum or best of 1..Kmax."),
        click.option("--time-scale", default="duration", show_default=True,
                     help="GMM-AS 4th coordinate: 'duration' (t normalised to 0..1) or units per second (1 = s)."),
        click.option("--reg-space", default=0.005, show_default=True, type=float,
                     help="GMM-AS spatial std floor (m) added to covariances."),
        click.option("--reg-time", default=0.1, show_default=True, type=float,
                     help="GMM-AS time std floor, in --time-scale units."),
        click.option("--saliency", default="precision", show_default=True,
                     type=click.Choice(["precision", "literal", "weight", "conditional"]),
                     help="GMM-AS saliency reading (see kinfu_cli/attention/gmm_as.py; 'literal' = eq. 13 on "
                          "the spatial covariance)."),
        click.option("--threshold-mode", default="available", show_default=True,
                     type=click.Choice(["available", "literal"]),
                     help="GMM-AS: mean of existing neighbours, or sum / 2 Lambda as printed in Alg. 3."),
        click.option("--resample", default=300, show_default=True, type=int,
                     help="GMM-AS: resample each trajectory to this many samples (0 = raw samples)."),
        click.option("--noise-floor", default=1.0, show_default=True, type=float,
                     help="GMM-AS: raise the floor to this x the estimated sensor noise, denoising first (0 = off)."),
        click.option("--literal", is_flag=True,
                     help="The paper read literally: GMM-AS on raw samples, t in s, 1 mm floor, eq. 13 on the "
                          "spatial covariance, POITh 2.5, sum / 2 Lambda; ZVC with ZVCTh 1.72. Overrides those options."),
        click.option("--zvc-half-width", default=4, show_default=True, type=int, help="ZVC B (filter width 2B+1)."),
        click.option("--zvc-threshold", default=1.5, show_default=True, type=float,
                     help="ZVC ZVCTh (paper 1.72; 1.5 re-calibrated on users 1+4, see attention/zvc.py)."),
        click.option("--zvc-r1", default=0.10, show_default=True, type=float, help="ZVC inner radius r1 (m)."),
        click.option("--zvc-r2", default=0.25, show_default=True, type=float, help="ZVC outer radius r2 (m)."),
        click.option("--radius", default=0.2, show_default=True, type=float, help="Region radius of each POI (m)."),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f


def detector_params(kw: dict) -> dict:
    """{"gmm-as": {...}, "zvc": {...}} constructor keywords from the parsed options (removed from kw)."""
    g = {k: kw.pop(k) for k in ("poi_threshold", "neighbours", "bic_threshold", "max_components", "selection",
                                "reg_space", "reg_time", "saliency", "threshold_mode", "resample", "noise_floor")}
    g["time_scale"] = _time_scale(kw.pop("time_scale"))
    literal = kw.pop("literal")
    if literal:
        from kinfu_cli.attention.gmm_as import GmmActivitySaliency

        g.update(GmmActivitySaliency.LITERAL)
    radius = kw.pop("radius")
    g["radius"] = radius
    z = {"half_width": kw.pop("zvc_half_width"), "threshold": kw.pop("zvc_threshold"), "r1": kw.pop("zvc_r1"),
         "r2": kw.pop("zvc_r2"), "radius": radius}
    if literal:
        from kinfu_cli.attention.zvc import PAPER_THRESHOLD

        z["threshold"] = PAPER_THRESHOLD
    return {"gmm-as": g, "zvc": z}


def load_trajectory(path: Path, hand_topic: str | None, hand_frame: str | None, world_frame: str | None):
    """A `.traj` file or the hand trajectory of a recording (via the IO layer)."""
    from kinfu_cli.io.hand import load_hand_trajectory

    return load_hand_trajectory(path, hand_topic=hand_topic, hand_frame=hand_frame, world_frame=world_frame)


def detect_tasks(traj, algorithm: str, params: dict, workspace=None, max_gap_s: float | None = 2.0,
                 min_duration_s: float | None = None, quiet: bool = True):
    """attention.tasks.detect_by_task with a fresh `algorithm` detector (constructor `params`) per task."""
    from kinfu_cli.attention.tasks import MIN_DURATION_S, detect_by_task
    from kinfu_cli.evaluation.poi import make_detector

    make_detector(algorithm, params)._check()  # bad detector options fail before any work
    return detect_by_task(traj, lambda: make_detector(algorithm, params), workspace, max_gap_s,
                          MIN_DURATION_S if min_duration_s is None else min_duration_s, quiet=quiet)


def _min_task(value: float) -> float:
    if not value >= 0:
        raise ConfigError(f"--min-task: expected seconds >= 0, got {value}")
    return value


@click.command("poi", short_help="Points of interest from the hand trajectory (GMM-AS or ZVC).")
@click.argument("source", metavar="RECORDING_OR_TRAJ", type=click.Path(path_type=Path))
@click.option("--algorithm", default="gmm-as", show_default=True, type=click.Choice(["gmm-as", "zvc"]),
              help="Detector.")
@click.option("--hand-topic", default=None, help="Pose topic of the hand [default: detected by name].")
@click.option("--hand-frame", default=None, help="TF frame of the hand (instead of a topic).")
@click.option("--world-frame", default=None, help="Frame to express the trajectory and POIs in.")
@click.option("--workspace", default=None, metavar="X0,Y0,Z0,X1,Y1,Z1",
              help="Workspace box (metres, trajectory frame): a task is a run of samples inside it; each task "
                   "is analysed on its own, as the paper's recorder does [default: everywhere].")
@click.option("--split-gap", default=2.0, show_default=True, type=float, metavar="SECONDS",
              help="Also start a new task after a pause in the samples longer than this (0 = never).")
@click.option("--min-task", default=0.5, show_default=True, type=float, metavar="SECONDS",
              help="Drop runs shorter than this (hand crossing a corner of the box, tracker glitches).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=Path("pois.json"),
              show_default=True, help="pois.json to write (read by kinfu nbv --pois and kinfu fuse --clear-pois).")
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="PNG: trajectory, Gaussians coloured by saliency (or ZVC slow segments) and the POIs; "
                   "with several tasks, the tasks in colour and their time spans.")
@click.option("--json", "as_json", is_flag=True, help="Print the pois.json object on stdout.")
@click.option("--quiet", is_flag=True, help="No progress output.")
@detector_options
def command(source, algorithm, hand_topic, hand_frame, world_frame, workspace, split_gap, min_task, output, plot,
            as_json, quiet, **kw):
    """Find where the person acted (placed, removed, picked an object) from the wrist trajectory.

    GMM-AS (Monica et al. 2016, Alg. 3) fits a Gaussian mixture on (x, y, z, t), picks the number of
    Gaussians by BIC, and marks the Gaussians much more salient than their neighbours; ZVC marks
    where the hand is much slower locally than around it. Input: a Polhemus `.traj` file or a
    recording (MCAP, ROS 1 .bag, ROS 2 folder) with a hand pose topic or TF frame. Writes pois.json:
    position, time, saliency, region radius and (GMM-AS) the Gaussian of each POI.

    A long stream is first cut into tasks, as the paper's recorder does: runs of samples inside
    --workspace, split at pauses longer than --split-gap; each task goes through the detector on its
    own. pois.json then also lists the tasks (index, t_start, t_end, samples, n_pois) and each POI
    its task.

    \b
    Example:
      kinfu poi recording.mcap -o out/pois.json --plot out/pois.png
      kinfu poi user1_cup0.traj --algorithm zvc --json
      kinfu poi recording.bag --hand-topic /hand/pose --poi-threshold 2.5
      kinfu poi session.mcap --workspace -0.5,-0.8,0.7,0.6,0.4,1.3 --split-gap 1
      kinfu poi user1_cup0.traj --literal --plot literal.png
    """
    from kinfu_cli.core.pois import pois_document
    from kinfu_cli.attention.tasks import parse_workspace, task_entries
    from kinfu_cli.evaluation.poi import make_detector
    from kinfu_cli.core.atomic import write_json

    params = detector_params(kw)[algorithm]
    box = parse_workspace(workspace)
    if not split_gap >= 0:
        raise ConfigError(f"--split-gap: expected seconds >= 0 (0 = never split on pauses), got {split_gap}")
    _min_task(min_task)
    make_detector(algorithm, params)._check()  # every option checked before the trajectory is read
    traj = load_trajectory(source, hand_topic, hand_frame, world_frame)
    tasks, detectors, pois = detect_tasks(traj, algorithm, params, box, split_gap, min_task, quiet=quiet)
    recorded = dict(detectors[0].get_params())
    if algorithm == "gmm-as":
        recorded["n_components"] = int(sum(d.n_components_ for d in detectors))  # per task in "tasks"
    doc = pois_document(pois, algorithm, recorded, frame=traj.frame, source=str(source))
    doc["tasks"] = entries = task_entries(tasks, detectors)
    doc["tasks_dropped"] = tasks.dropped
    doc["task_split"] = {"workspace": list(box) if box else None, "split_gap": float(split_gap),
                         "min_task": float(min_task)}
    write_json(output, doc)
    if plot is not None:
        from kinfu_cli.report.poi_plot import plot_pois, plot_task_pois

        title = f"{Path(str(source)).name} ({algorithm})"
        if len(tasks) == 1 and tasks[0].samples == len(traj):
            plot_pois(plot, traj, detectors[0], title=title)
        else:
            plot_task_pois(plot, traj, tasks, detectors, workspace=box, title=title)
    if as_json:
        click.echo(json.dumps(doc, indent=2))
    elif not quiet:
        if len(detectors) == 1 and not tasks.dropped:
            extra = f", K = {detectors[0].n_components_} Gaussians" if algorithm == "gmm-as" else ""
            click.echo(f"{len(pois)} POI(s) from {len(traj)} samples ({algorithm}{extra}) -> {output}")
        else:
            dropped = f", {tasks.dropped} short run(s) dropped" if tasks.dropped else ""
            click.echo(f"{len(pois)} POI(s) in {len(tasks)} task(s) from {len(traj)} samples ({algorithm}{dropped})"
                       f" -> {output}")
            for e in entries:
                k = f", K = {e['n_components']}" if algorithm == "gmm-as" else ""
                click.echo(f"  task {e['index']}: t = {e['t_start']:.2f} .. {e['t_end']:.2f} s, {e['samples']} samples"
                           f"{k}, {e['n_pois']} POI(s)")
        for p in pois:
            x, y, z = p.position
            click.echo(f"  #{p.id}: ({x:.3f}, {y:.3f}, {z:.3f}) m at t = {p.time:.2f} s, saliency {p.saliency:.4g}"
                       + (f", task {p.extra['task']}" if len(tasks) > 1 else ""))
