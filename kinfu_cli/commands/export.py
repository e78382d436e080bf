"""`kinfu export`: the assembled RGB-D frames of a recording as a 7-Scenes-layout folder."""

from __future__ import annotations

import json

import click

from kinfu_cli.io.rgbd_folders import export_frames
from kinfu_cli.io.roles import role_kwargs, role_options


@click.command("export", short_help="Write a recording's RGB-D frames (depth, colour, pose, K) as a frame folder.")
@click.argument("recording", type=click.Path(exists=False))
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder (7-Scenes layout: frame-N.depth.png, .color.png, .pose.txt, camera-intrinsics.txt).")
@click.option("--pose-source", type=click.Choice(["tf", "topic", "none"]), default="tf", show_default=True,
              help="Camera poses from TF (world frame <- camera frame), a pose topic, or none.")
@click.option("--pose-topic", default=None, metavar="TOPIC", help="Camera pose topic for --pose-source topic.")
@click.option("--tolerance", default=0.05, show_default=True, type=float,
              help="Largest depth/colour stamp difference and pose extrapolation (s).")
@click.option("--start", "start_s", default=None, type=float, help="Start, seconds from the recording start.")
@click.option("--end", "end_s", default=None, type=float, help="End, seconds from the recording start.")
@click.option("--every", default=1, show_default=True, type=int, help="Keep every n-th depth frame.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary (stats, roles, frame list) as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@role_options
def command(recording: str, out: str, pose_source: str, pose_topic: str | None, tolerance: float,
            start_s: float | None, end_s: float | None, every: int, as_json: bool, quiet: bool, **kwargs) -> None:
    """Assemble the RGB-D frames of RECORDING (depth paired with the nearest colour image and the camera
    pose at the depth stamp) and write them as a frame folder that `kinfu import` and other RGB-D tools
    read. Depth is written in millimetres; frames.json lists stamps and the dropped frames by reason.

    \b
    Example:
      kinfu export sample_data/tabletop/recording.mcap -o tabletop_frames/
      kinfu export run.bag -o frames/ --every 5 --camera-frame camera_depth_optical_frame
    """
    summary = export_frames(recording, out, roles_kw=role_kwargs(kwargs), pose_source=pose_source,
                            pose_topic=pose_topic, tolerance_s=tolerance, start_s=start_s, end_s=end_s,
                            every=every, quiet=quiet)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    st = summary["stats"]
    dropped = ", ".join(f"{n} {r}" for r, n in st["dropped"].items()) or "none"
    click.echo(f"wrote {summary['output']}: {summary['frames']} frames of {st['depth_messages']} depth messages "
               f"(skipped {st['skipped']}, without colour {st['without_color']}; dropped: {dropped})")
