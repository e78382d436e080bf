"""`kinfu info`: what is in a recording — topics, types, counts, rates, time span, roles, TF tree."""

from __future__ import annotations

import json

import click

from kinfu_cli.commands._frames import frame_kwargs, frame_options
from kinfu_cli.commands._options import Inapplicable, check_inapplicable
from kinfu_cli.commands._output import print_warnings, with_option_warnings
from kinfu_cli.commands._roles import role_kwargs, role_options
from kinfu_cli.io.summary import format_summary, recording_summary

ROLES_HEADING = "roles (detected; override with --depth-topic, --world-frame, ...):"
# the frame options assemble the frames, which only --frames does (commands._options.check_inapplicable)
INAPPLICABLE = (Inapplicable(("pose-source", "pose-topic", "tolerance", "start", "end", "every"),
                             lambda p: None if p["check"] else "without --frames",
                             "with --frames (only it assembles the RGB-D frames)"),)


@click.command("info", short_help="Show topics, rates, time span, detected roles and TF tree of a recording.")
@click.argument("recording", type=click.Path(exists=False))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON on stdout.")
@click.option("--frames", "check", is_flag=True,
              help="Also assemble every RGB-D frame (decodes all images) and report how many are usable and why "
                   "the others are dropped; the frame options below apply.")
@frame_options
@click.option("-q", "--quiet", is_flag=True, help="No progress bar (with --frames).")
@role_options
def command(recording: str, as_json: bool, check: bool, quiet: bool, **kwargs) -> None:
    """Summarise RECORDING (MCAP file, ROS 1 .bag or ROS 2 bag folder): topics with message types, counts
    and rates, the time span, the topics and frames detected for each role (depth, colour, camera info,
    camera frame, world frame, hand) and the TF frame tree.

    \b
    Example:
      kinfu info sample_data/tabletop/recording.mcap
      kinfu info recording_ros2/ --json > summary.json
      kinfu info run.bag --frames --tolerance 0.02
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    fk = frame_kwargs(kwargs)
    summary = recording_summary(recording, check_frames=fk if check else None, quiet=quiet, **role_kwargs(kwargs))
    print_warnings(with_option_warnings(summary))  # the frames' (--frames), as fuse and export print them
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        click.echo(format_summary(summary, roles_heading=ROLES_HEADING))
