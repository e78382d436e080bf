"""`kinfu import`: an RGB-D frame folder (7-Scenes/3DMatch or TUM layout) into a recording."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinfu_cli.commands._options import (Inapplicable, OutputPath, check_inapplicable, claim_outputs, comma_items,
                                         force_option)
from kinfu_cli.commands._output import print_warnings, with_option_warnings
from kinfu_cli.commands._up import parse_up
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.rgbd_folders import import_folder
from kinfu_cli.io.writers import format_for


def _ros2_out(p: dict) -> str | None:
    """'with a ROS 2 bag folder as --out' when -o names one (a name the writer refuses is its own error)."""
    try:
        return "with a ROS 2 bag folder as --out" if format_for(Path(p["out"])) == "ros2" else None
    except ConfigError:
        return None


# a ROS 2 bag (sqlite3) is written without chunk compression either way (commands._options.check_inapplicable)
INAPPLICABLE = (Inapplicable(("no-compress",), _ros2_out, "to an MCAP or .bag recording (zstd / lz4 chunks)"),)


@click.command("import", short_help="Convert an RGB-D frame folder (7-Scenes/3DMatch, TUM) into MCAP/bag/ROS 2.")
@click.argument("folder", type=click.Path(exists=False, file_okay=False))
@click.option("-o", "--out", "out", required=True, type=OutputPath(kind="recording", path_type=str),
              help="Output recording: NAME.mcap, NAME.bag, or a folder name for a ROS 2 bag (sqlite3).")
@click.option("--rate", default=30.0, show_default=True, type=float,
              help="Frame rate (Hz) giving stamps t = N / rate for folders without stamps (7-Scenes).")
@click.option("--frames", default=None, metavar="N|A:B[:S]",
              help="Frames to import: the first N, or a slice A:B:STEP of the sorted frame list [all].")
@click.option("--color", type=click.Choice(["compressed", "raw", "none"]), default="compressed", show_default=True,
              help="Colour as the data set's own jpeg/png bytes (CompressedImage), as rgb8 Image, or not at all.")
@click.option("--intrinsics", default=None, metavar="FX,FY,CX,CY",
              help="Depth camera intrinsics when the folder has no intrinsics file.")
@click.option("--up", default=None, metavar="X,Y,Z",
              help="Direction against gravity in the folder's pose frame, when known [not known: `kinfu fuse` "
                   "estimates it].")
@click.option("--no-compress", is_flag=True, help="Do not compress chunks (zstd for MCAP, lz4 for .bag).")
@click.option("--json", "as_json", is_flag=True, help="Print the import summary as JSON on stdout.")
@click.option("-q", "--quiet", is_flag=True, help="Only warnings and errors: no progress bar, no summary (--json still prints the JSON).")
@force_option
def command(folder: str, out: str, rate: float, frames: str | None, color: str, intrinsics: str | None,
            up: str | None, no_compress: bool, as_json: bool, quiet: bool, force: bool) -> None:
    """Convert the RGB-D frame FOLDER into a recording that every kinfu command reads.

    Layouts: 7-Scenes/3DMatch (frame-N.depth.png, frame-N.color.png|jpg, frame-N.pose.txt,
    camera-intrinsics.txt or intrinsics.K.txt) and TUM RGB-D (depth.txt, rgb.txt, groundtruth.txt).
    The recording holds /camera/depth/image_raw (16UC1 mm), /camera/depth/camera_info, colour on
    /camera/color/image_raw/compressed, /tf world -> camera_optical from the poses, and /kinfu/world_up:
    the --up direction, or zero when not given ("world" is the data set's frame, often the first camera,
    not a z-up REP-103 frame). A 7-Scenes frame without a usable pose (pose file missing, -inf or NaN)
    among posed frames is left out, with a warning, rather than given a pose interpolated by fusion.

    \b
    Example:
      kinfu import ../shared/data/rgbd-7scenes-redkitchen -o redkitchen.mcap
      kinfu import tum_fr1_desk/ -o fr1_desk.bag --frames 0:300:2
      kinfu import scans/ -o scans.mcap --up 0,-1,0
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    if intrinsics:  # an empty item ('525,,319.5,239.5'): the list options' error
        comma_items(intrinsics, "--intrinsics")
    # inside, the recording would join the data set it was made from (and be read by the next import)
    claim_outputs({"out": out}, [folder], force, recordings=[folder])
    summary = import_folder(folder, out, rate=rate, frames=frames, color=color, intrinsics=intrinsics,
                            compress=not no_compress, quiet=quiet, intrinsics_source="--intrinsics",
                            up=parse_up(up), force=force)
    print_warnings(with_option_warnings(summary))
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    if quiet:
        return
    left_out = f", {summary['frames_left_out']} left out without a pose" if summary["frames_left_out"] else ""
    click.echo(f"wrote {summary['output']} ({summary['format']}): {summary['frames']} of "
               f"{summary['frames_in_folder']} frames ({summary['layout']} layout{left_out}), "
               f"{summary['color_frames']} colour images, {summary['tf_samples']} TF samples {summary['topics']['tf']}")
    up_text = ",".join(f"{v:g}" for v in summary["up"]) if summary["up"] else "not known (kinfu fuse estimates it)"
    click.echo(f"world frame up: {up_text}, declared on {summary['topics']['world_up']}")
    for note in summary["notes"]:
        click.echo(f"note: {note}")
