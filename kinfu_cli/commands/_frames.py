"""The frame-assembly options of commands that stream RGB-D frames (io.frames.iter_frames)."""

from __future__ import annotations

from collections.abc import Callable

import click

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.frames import POSE_SOURCES

FRAME_OPTIONS = ("pose_source", "pose_topic", "tolerance_s", "start_s", "end_s", "every")


def frame_options(func: Callable) -> Callable:
    """click decorator adding --pose-source, --pose-topic, --tolerance, --start, --end, --every; hand the
    values to iter_frames with `iter_frames(rec, roles, **frame_kwargs(kwargs))`."""
    opts = [
        click.option("--pose-source", "pose_source", type=click.Choice(list(POSE_SOURCES)), default=None,
                     help="Camera poses from TF (world frame <- camera frame), a pose topic, or none [default: "
                          "topic with --pose-topic, else tf]."),
        click.option("--pose-topic", "pose_topic", default=None, metavar="TOPIC",
                     help="Camera pose topic (PoseStamped, Odometry, ...) for --pose-source topic."),
        click.option("--tolerance", "tolerance_s", default=0.05, show_default=True, type=float,
                     help="Largest depth/colour stamp difference, and how far a pose may be extrapolated (s)."),
        click.option("--start", "start_s", default=None, type=float, help="Start, seconds from the recording start."),
        click.option("--end", "end_s", default=None, type=float, help="End, seconds from the recording start."),
        click.option("--every", "every", default=1, show_default=True, type=int,
                     help="Use every n-th depth frame."),
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


def frame_kwargs(kwargs: dict) -> dict:
    """Pop the frame options out of a command's kwargs (for iter_frames); a pose topic given means pose source
    topic, and goes with no other (it used to be ignored without a word)."""
    out = {name: kwargs.pop(name) for name in FRAME_OPTIONS if name in kwargs}
    if "pose_source" in out:
        topic = out.get("pose_topic")
        out["pose_source"] = out["pose_source"] or ("topic" if topic else "tf")
        if topic and out["pose_source"] != "topic":
            raise ConfigError(f"a pose topic is read only with pose source 'topic', not {out['pose_source']!r}",
                              parameter="pose_topic")
    return out
