"""`kinfu export`: the assembled RGB-D frames of a recording as a 7-Scenes-layout folder, or (`--trajectory tum`)
its camera poses, or a fuse output's, as a TUM trajectory file for evo."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinfu_cli.commands._options import OutputPath, bag_folder, claim_outputs, force_option
from kinfu_cli.commands._output_path import output_kind_problem
from kinfu_cli.commands._output import print_warnings
from kinfu_cli.commands._frames import frame_kwargs, frame_options
from kinfu_cli.commands._roles import role_kwargs, role_options
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.rgbd_folders import dropped_frames_warning, export_frames
from kinfu_cli.io.tum import fused_trajectory, recording_trajectory, write_tum


@click.command("export", short_help="Write a recording's RGB-D frames as a frame folder, or a TUM trajectory.")
@click.argument("recording", metavar="RECORDING_OR_FUSE_DIR", type=click.Path(exists=False))
@click.option("-o", "--out", "out", required=True, type=OutputPath(path_type=str),
              help="Output folder (7-Scenes layout: frame-N.depth.png, .color.png, .pose.txt, camera-intrinsics.txt); "
                   "with --trajectory the trajectory file.")
@click.option("--trajectory", type=click.Choice(["tum"]), default=None,
              help="Write only the camera trajectory, as a TUM file (timestamp tx ty tz qx qy qz qw, seconds, "
                   "camera-to-world): of a recording, its poses (TF or --pose-topic) at each depth frame; of a "
                   "`kinfu fuse` output folder, the poses it fused. For evo_ape tum gt.tum est.tum.")
@frame_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary (stats, roles, frame list) as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="Only warnings and errors: no progress bar, no summary (--json still prints the JSON).")
@role_options
@force_option
def command(recording: str, out: str, trajectory: str | None, as_json: bool, quiet: bool, force: bool,
            **kwargs) -> None:
    """Assemble the RGB-D frames of RECORDING (depth paired with the nearest colour image and the camera
    pose at the depth stamp) and write them as a frame folder that `kinfu import` and other RGB-D tools
    read. Depth is written in millimetres; frames.json lists stamps and the dropped frames by reason.

    With --trajectory tum, OUT is one TUM trajectory file instead: the recording's camera poses at the
    depth frames (the ground truth), or, from a `kinfu fuse` output folder, the poses it fused (its
    trajectory.tum, ICP's estimate with --pose icp/hint). Stamps are the recording's, so evo lines them up.

    \b
    Example:
      kinfu export sample_data/tabletop/recording.mcap -o tabletop_frames/
      kinfu export run.bag -o frames/ --every 5 --camera-frame camera_depth_optical_frame
      kinfu export run.mcap --trajectory tum -o gt.tum
      kinfu export out/fuse_icp --trajectory tum -o est.tum   # then: evo_ape tum gt.tum est.tum -a
    """
    # inside a ROS 2 bag folder it would join the recording; inside a fuse output, the next fuse run replaces it
    claim_outputs({"out": out}, [recording, bag_folder(recording)], force, recordings=[recording])
    problem = output_kind_problem(out, "trajectory" if trajectory else "folder")
    if problem is not None:  # the frame folder named like a file (-o frames.json, -o traj.tum without --trajectory)
        raise ConfigError(problem, parameter="out")
    fk = frame_kwargs(kwargs)
    if trajectory is not None:
        _export_trajectory(recording, out, fk, role_kwargs(kwargs), as_json, quiet)
        return
    summary = export_frames(recording, out, roles_kw=role_kwargs(kwargs), quiet=quiet, force=force, **fk)
    print_warnings(summary)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    if quiet:
        return
    st = summary["stats"]
    dropped = ", ".join(f"{n} {r}" for r, n in st["dropped"].items()) or "none"
    click.echo(f"wrote {summary['output']}: {summary['frames']} frames of {st['depth_messages']} depth messages "
               f"(skipped {st['skipped']}, without colour {st['without_color']}; dropped: {dropped})")


def _export_trajectory(source: str, out: str, fk: dict, roles_kw: dict, as_json: bool, quiet: bool) -> None:
    """--trajectory tum: a fuse output folder's trajectory.tum, or the recording's poses at its depth frames."""
    if Path(source).is_dir() and (Path(source) / "report.json").is_file():
        stamps, poses = fused_trajectory(source)
        summary = {"source": str(source), "kind": "fused", "poses": len(stamps)}
        comment = f"kinfu export {source}: the poses kinfu fuse fused"
    else:
        stamps, poses, info = recording_trajectory(source, roles_kw, quiet=quiet, **fk)
        summary = {"source": str(source), "kind": "recording", "poses": len(stamps), "pose_source": fk.get("pose_source"),
                   "world_frame": info["world_frame"], "stats": info["stats"], "warnings": info["warnings"]}
        comment = (f"kinfu export {source}: the recording's camera poses ({fk.get('pose_source')}) at "
                   f"{info.get('sampled_at', 'depth frames')}")
        summary["sampled_at"] = info.get("sampled_at")
        if dropped := _dropped_warning(source, info["stats"]):
            summary["warnings"] = summary["warnings"] + [dropped]
    write_tum(out, stamps, poses, comment=comment)
    summary["output"] = str(out)
    print_warnings(summary)
    if len(stamps):
        summary["t_start_s"], summary["t_end_s"] = float(stamps[0]) * 1e-9, float(stamps[-1]) * 1e-9
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    elif not quiet:
        click.echo(f"wrote {out}: {len(stamps)} camera poses ({summary['kind']}) as TUM")


def _dropped_warning(source: str, stats: dict) -> str | None:
    """The depth frames left out of a recording's trajectory, by reason: a TUM file holds no line for them, and
    evo then scores a shorter trajectory without a word."""
    return dropped_frames_warning(source, stats, "the trajectory has no pose")
