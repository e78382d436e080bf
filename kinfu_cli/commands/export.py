"""`kinfu export`: the assembled RGB-D frames of a recording as a 7-Scenes-layout folder."""

from __future__ import annotations

import json

import click

from kinfu_cli.commands._options import claim_outputs, force_option
from kinfu_cli.commands._frames import frame_kwargs, frame_options
from kinfu_cli.commands._roles import role_kwargs, role_options
from kinfu_cli.io.rgbd_folders import export_frames


@click.command("export", short_help="Write a recording's RGB-D frames (depth, colour, pose, K) as a frame folder.")
@click.argument("recording", type=click.Path(exists=False))
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder (7-Scenes layout: frame-N.depth.png, .color.png, .pose.txt, camera-intrinsics.txt).")
@frame_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary (stats, roles, frame list) as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@role_options
@force_option
def command(recording: str, out: str, as_json: bool, quiet: bool, force: bool, **kwargs) -> None:
    """Assemble the RGB-D frames of RECORDING (depth paired with the nearest colour image and the camera
    pose at the depth stamp) and write them as a frame folder that `kinfu import` and other RGB-D tools
    read. Depth is written in millimetres; frames.json lists stamps and the dropped frames by reason.

    \b
    Example:
      kinfu export sample_data/tabletop/recording.mcap -o tabletop_frames/
      kinfu export run.bag -o frames/ --every 5 --camera-frame camera_depth_optical_frame
    """
    claim_outputs({"out": out}, [recording], force)
    fk = frame_kwargs(kwargs)
    summary = export_frames(recording, out, roles_kw=role_kwargs(kwargs), quiet=quiet, **fk)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    st = summary["stats"]
    dropped = ", ".join(f"{n} {r}" for r, n in st["dropped"].items()) or "none"
    click.echo(f"wrote {summary['output']}: {summary['frames']} frames of {st['depth_messages']} depth messages "
               f"(skipped {st['skipped']}, without colour {st['without_color']}; dropped: {dropped})")
