"""The role options shared by commands that read a recording: which topic / frame plays which part.

Each defaults to None (auto-detect, io.roles.detect_roles); `role_kwargs` hands the values over.
"""

from __future__ import annotations

from collections.abc import Callable

import click

from kinfu_cli.commands._options import comma_items

ROLE_HELP = {
    "depth_topic": "Depth topic (sensor_msgs/Image 16UC1/32FC1, compressedDepth, or an organized PointCloud2) [auto].",
    "color_topic": "Colour image topic (Image or jpeg/png CompressedImage) [auto].",
    "info_topic": "sensor_msgs/CameraInfo topic of the depth camera [auto].",
    "camera_frame": "TF frame of the depth camera [frame_id of the depth images].",
    "world_frame": "TF frame poses are expressed in [world, map, odom or the TF root].",
    "hand_topic": "Hand pose topic (PoseStamped, PoseWithCovarianceStamped, Odometry, TransformStamped) [auto].",
    "hand_frame": "TF frame of the hand, when the hand comes as TF [auto].",
}


def role_options(func: Callable) -> Callable:
    """click decorator adding --depth-topic, --color-topic, --info-topic, --camera-frame, --world-frame,
    --hand-topic, --hand-frame (each default None = auto-detect) and --intrinsics. Pass the values to
    `detect_roles(rec, **kw)` with `role_kwargs(kwargs)`."""
    func = click.option("--intrinsics", "intrinsics", default=None, metavar="FX,FY,CX,CY",
                        help="Depth camera intrinsics in pixels, for a recording without its CameraInfo (or to "
                             "override it; not with --info-topic).")(func)
    for name in reversed(ROLE_HELP):
        func = click.option(f"--{name.replace('_', '-')}", name, default=None, metavar="NAME",
                            help=ROLE_HELP[name])(func)
    return func


def role_kwargs(kwargs: dict) -> dict:
    """Pop the role options out of a command's kwargs (for detect_roles); an empty item of --intrinsics
    ('525,,319.5,239.5') is the list options' error."""
    out = {name: kwargs.pop(name, None) for name in (*ROLE_HELP, "intrinsics")}
    if out["intrinsics"]:
        comma_items(out["intrinsics"], "--intrinsics")
    return out
