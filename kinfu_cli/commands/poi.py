"""`kinfu poi`: points of interest (where the person acted) from the hand trajectory, GMM-AS or ZVC."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinfu_cli.attention.detect import PoiDetection, check_detection, detect_pois
from kinfu_cli.attention.tasks import MIN_TASK_S, SPLIT_GAP_S
from kinfu_cli.commands._detector_options import detector_inapplicable, detector_options, detector_params_from
from kinfu_cli.commands._options import (OutputPath, bag_folder, check_inapplicable, claim_outputs, comma_items,
                                         force_option)
from kinfu_cli.commands._output import print_warnings, with_option_warnings
from kinfu_cli.core.atomic import write_json
from kinfu_cli.report.poi_plot import plot_pois, plot_task_pois


# options of the detector --algorithm did not choose, or that --literal / the ZVC rule in force override
INAPPLICABLE = detector_inapplicable(lambda p: {p["algorithm"]})


def detection_arguments(params: dict) -> dict:
    """detect_pois's detector arguments from the command's parsed options (click's parameter dict): the one
    place that turns poi's options into them, for the command and for `check_options`."""
    if params["workspace"]:  # an empty item ('0,,0,...') is the list options' error (the reader skipped it)
        comma_items(params["workspace"], "--workspace")
    return dict(algorithm=params["algorithm"], params=detector_params_from(dict(params))[params["algorithm"]],
                workspace=params["workspace"], split_gap=params["split_gap"], min_task=params["min_task"])


def check_options(params: dict) -> None:
    """What `kinfu poi` refuses with these options before it reads the trajectory (kinfu batch checks a plan
    with it); ConfigError naming the parameter."""
    check_detection(**detection_arguments(params))


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
@click.option("--split-gap", default=SPLIT_GAP_S, show_default=True, type=float, metavar="SECONDS",
              help="Also start a new task after a pause in the samples longer than this (0 = never).")
@click.option("--min-task", default=MIN_TASK_S, show_default=True, type=float, metavar="SECONDS",
              help="Drop runs shorter than this (hand crossing a corner of the box, tracker glitches).")
@click.option("-o", "--output", type=OutputPath(dir_okay=False, kind="json"), default=Path("pois.json"),
              show_default=True, help="pois.json to write (read by kinfu nbv --pois and kinfu fuse --clear-pois).")
@click.option("--plot", type=OutputPath(dir_okay=False, kind="image"), default=None,
              help="PNG: trajectory, Gaussians coloured by saliency (or ZVC slow segments) and the POIs; "
                   "with several tasks, the tasks in colour and their time spans.")
@click.option("--viz", type=OutputPath(dir_okay=False, kind="viewer"), default=None,
              help="Also write a viewer file: an MCAP of Foxglove messages (hand trajectory and POIs); open it in Foxglove.")
@click.option("--json", "as_json", is_flag=True, help="Print the pois.json object on stdout.")
@click.option("--quiet", is_flag=True, help="No progress output.")
@detector_options
@force_option
def command(source, algorithm, hand_topic, hand_frame, world_frame, workspace, split_gap, min_task, output, plot,
            as_json, quiet, force, viz=None, **kw):
    """Find where the person acted (placed, removed, picked an object) from the wrist trajectory.

    GMM-AS (Monica et al. 2016, Alg. 3) fits a Gaussian mixture on (x, y, z, t), picks the number of
    Gaussians by BIC, and marks the Gaussians much more salient than their neighbours; ZVC marks
    where the hand's local speed falls below a share of the task's own transport speed (--zvc-rule
    relative, default) or is much slower than around it (the paper's ratio rule, --zvc-threshold). Input: a Polhemus `.traj` file or a
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
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    claim_outputs({"output": output, "plot": plot, "viz": viz}, [source, bag_folder(source)], force,
                  recordings=[source])
    found = detect_pois(source, **detection_arguments(click.get_current_context().params), hand_topic=hand_topic,
                        hand_frame=hand_frame, world_frame=world_frame, quiet=quiet)
    write_json(output, with_option_warnings(found.document))
    print_warnings(found.document)
    if plot is not None:
        title = f"{Path(str(source)).name} ({algorithm})"
        if found.whole_trajectory:
            plot_pois(plot, found.trajectory, found.detectors[0], title=title)
        else:
            plot_task_pois(plot, found.trajectory, found.tasks, found.detectors, workspace=found.workspace,
                           title=title)
    if viz is not None:
        from kinfu_cli.report.viewer import write_viewer  # protobuf and segmentation: only for --viz

        write_viewer(viz, pois=found)
    if as_json:
        click.echo(json.dumps(found.document, indent=2))
    elif not quiet:
        for line in _summary_lines(found, output):
            click.echo(line)


def _summary_lines(found: PoiDetection, output: Path) -> list[str]:
    """What was found: POI count (per task when the stream was cut), then one line per POI."""
    algorithm, tasks, detectors, pois = found.algorithm, found.tasks, found.detectors, found.pois
    samples = len(found.trajectory)
    if len(detectors) == 1 and not tasks.dropped:
        extra = f", K = {detectors[0].n_components_} Gaussians" if algorithm == "gmm-as" else ""
        lines = [f"{len(pois)} POI(s) from {samples} samples ({algorithm}{extra}) -> {output}"]
    else:
        dropped = f", {tasks.dropped} short run(s) dropped" if tasks.dropped else ""
        lines = [f"{len(pois)} POI(s) in {len(tasks)} task(s) from {samples} samples ({algorithm}{dropped})"
                 f" -> {output}"]
        for e in found.document["tasks"]:
            k = f", K = {e['n_components']}" if algorithm == "gmm-as" else ""
            lines.append(f"  task {e['index']}: t = {e['t_start']:.2f} .. {e['t_end']:.2f} s, {e['samples']} samples"
                         f"{k}, {e['n_pois']} POI(s)")
    for p in pois:
        x, y, z = p.position
        rec_t = p.extra.get("recording_time_s")
        when = f"t = {p.time:.2f} s" + (f" ({rec_t:.2f} s into the recording)" if rec_t is not None else "")
        lines.append(f"  #{p.id}: ({x:.3f}, {y:.3f}, {z:.3f}) m at {when}, saliency {p.saliency:.4g}"
                     + (f", task {p.extra['task']}" if len(tasks) > 1 else ""))
    return lines
