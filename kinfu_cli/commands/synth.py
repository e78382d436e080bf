"""`kinfu synth`: a synthetic tabletop recording (MCAP, ROS 1 bag, ROS 2 bag) with its ground truth."""

from __future__ import annotations

import json

import click

from kinfu_cli.commands._options import (Inapplicable, OutputPath, check_inapplicable, claim_outputs, comma_items,
                                         force_option)
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.synth import FORMAT_NAMES, synthesize


def parse_formats(text: str) -> list[str]:
    """'mcap,bag,ros2' -> ['mcap', 'bag', 'ros2'] (ConfigError naming --formats for anything else)."""
    items = [t.lower() for t in comma_items(text, "--formats")]
    bad = [t for t in items if t not in FORMAT_NAMES]
    if not items or bad:
        raise ConfigError(f"--formats {text!r}: expected a comma-separated subset of mcap,bag,ros2")
    return list(dict.fromkeys(items))


# options given where they do nothing (commands._options.check_inapplicable): the room scene has no arm, no hand and
# no objects to count; objects and household lay out their own objects; only the room turns its world
INAPPLICABLE = (
    Inapplicable(("scenario", "n-objects", "hand-rate"), lambda p: "with --scene room" if p["scene"] == "room"
                 else None, "to the arm scenes (--scene tabletop, objects, household)"),
    Inapplicable(("n-objects",), lambda p: f"with --scene {p['scene']}" if p["scene"] in ("objects", "household")
                 else None, "to --scene tabletop (objects and household lay out their own)"),
    Inapplicable(("world",), lambda p: None if p["scene"] == "room" else f"with --scene {p['scene']}",
                 "to --scene room (the arm scenes are z-up)"),
    Inapplicable(("jpeg-quality",), lambda p: None if p["color_format"] == "jpeg"
                 else f"with --color-format {p['color_format']}", "to --color-format jpeg"),
)


@click.command("synth", short_help="Write a synthetic tabletop or room recording (MCAP, bag, ROS 2) with ground truth.")
@click.option("-o", "--out", "out", required=True, type=OutputPath(file_okay=False, kind="folder", path_type=str),
              help="Output folder (gets recording.mcap, recording.bag, recording_ros2/, ground_truth/).")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the scene, camera path, hand and noise.")
@click.option("--scene", type=click.Choice(["tabletop", "room", "objects", "household"]), default="tabletop", show_default=True,
              help="tabletop: the arm scenario; room: a handheld camera walking a loop through a furnished "
                   "5 x 4 m room (no arm, no hand); objects: the arm scenario on the segmentation ground-truth "
                   "table (stacked boxes, touching boxes of one colour, a mug, striped objects; no --n-objects); "
                   "household: the arm scenario on 5-11 YCB-like objects made of parts (drill, bottles with caps, "
                   "printed boxes, cans, bowl, mug; no --n-objects).")
@click.option("--world", type=click.Choice(["z-up", "y-down"]), default="z-up", show_default=True,
              help="Convention of the world frame (room scene): z-up (REP-103) or y-down (the room rotated so "
                   "up is -y); declared on /kinfu/world_up.")
@click.option("--width", default=None, type=int, help="Depth/colour image width (pixels) [320; room 160].")
@click.option("--height", default=None, type=int, help="Depth/colour image height (pixels) [240; room 120].")
@click.option("--frames", default=None, type=int,
              help="Depth frames in all: 2/3 initial scan, 1/3 after the change; room: views along the loop "
                   "[36; room 30].")
@click.option("--formats", default="mcap,bag,ros2", show_default=True, help="Containers to write: mcap, bag, ros2.")
@click.option("--scenario", type=click.Choice(["place", "remove", "pick-and-place"]), default="pick-and-place",
              show_default=True, help="What the hand does between the scan and the after-change views.")
@click.option("--n-objects", default=4, show_default=True, type=int, help="Objects on the table at the start.")
@click.option("--hand-rate", default=100.0, show_default=True, type=float, help="Rate of /hand/pose (Hz).")
@click.option("--frame-rate", default=5.0, show_default=True, type=float, help="Rate of the depth frames (Hz).")
@click.option("--noise/--no-noise", default=True, show_default=True, help="Kinect v1 noise model on the depth.")
@click.option("--depth-format", type=click.Choice(["png", "raw"]), default="png", show_default=True,
              help="png: compressedDepth CompressedImage; raw: 16UC1 Image (mm).")
@click.option("--color-format", type=click.Choice(["jpeg", "png", "raw"]), default="jpeg", show_default=True,
              help="jpeg/png: CompressedImage; raw: rgb8 Image.")
@click.option("--jpeg-quality", default=75, show_default=True, type=int, help="JPEG quality of the colour images.")
@click.option("--camera-pose-topic", default=None, metavar="TOPIC",
              help="Also write the true camera pose (PoseStamped, frame world, the depth optical frame) on TOPIC "
                   "at every depth frame stamp, for `kinfu fuse --pose topic` [none].")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary on stdout.")
@click.option("-q", "--quiet", is_flag=True, help="Only warnings and errors: no progress bar, no summary (--json still prints the JSON).")
@force_option
def command(out, scene, world, seed, width, height, frames, formats, scenario, n_objects, hand_rate, frame_rate, noise,
            depth_format, color_format, jpeg_quality, camera_pose_topic, as_json, quiet, force):
    """Write a synthetic tabletop recording (or a room-scale sequence) and its ground truth.

    A table with boxes, cylinders, spheres and meshes; a 6-joint arm carries a Kinect-like camera (TF chain
    world -> base_link -> link1..link6 -> wrist -> camera_optical) over an arc for the initial scan; a hand
    (/hand/pose, PoseStamped in world) places, removes or picks-and-places an object; then views of the change.
    Depth is ray cast with open3d plus the Kinect v1 noise model (Nguyen et al. 2012), stored as 16UC1 mm
    (compressedDepth PNG by default). OUT/ground_truth/ holds scene_before.ply, scene_after.ply,
    objects/<id>.ply (+ table.ply, floor.ply), changes.json, camera_poses.txt and hand.traj. Seeded and
    deterministic. With --camera-pose-topic TOPIC the recordings also carry the true camera poses as
    geometry_msgs/PoseStamped (frame world) at every depth frame stamp, for `kinfu fuse --pose topic`.

    --scene room writes a room-scale sequence instead: a 5 x 4 m floor, four 2.5 m walls with a door gap, a
    table, a sofa and a shelf; a handheld camera about 1.5 m high walks a loop looking across the room (TF
    world -> camera_optical, no arm, no hand). --world y-down rotates the room and every pose +90 degrees
    about x (up is -y); the recording declares its up direction on /kinfu/world_up, which fuse trusts.
    OUT/ground_truth/ then holds scene.ply, changes.json (room extent, up) and camera_poses.txt.

    \b
    Example:
      kinfu synth -o sample_data/tabletop
      kinfu synth -o /tmp/small --width 64 --height 48 --frames 6 --formats mcap --scenario place
      kinfu synth -o /tmp/posed --camera-pose-topic /camera/pose
      kinfu synth -o /tmp/room --scene room --world y-down --formats mcap
      kinfu synth -o /tmp/objects --scene objects --formats mcap
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    room = scene == "room"
    width = width if width is not None else (160 if room else 320)
    height = height if height is not None else (120 if room else 240)
    frames = frames if frames is not None else (30 if room else 36)
    claim_outputs({"out": out}, [], force)
    result = synthesize(out, seed=seed, width=width, height=height, frames=frames, formats=parse_formats(formats),
                        scenario=scenario, n_objects=n_objects, hand_rate=hand_rate, frame_rate=frame_rate,
                        noise=noise, depth_format=depth_format, color_format=color_format,
                        jpeg_quality=jpeg_quality, quiet=quiet, camera_pose_topic=camera_pose_topic, scene=scene,
                        world=world, force=force)
    summary = result.to_json()
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    elif quiet:
        return
    elif room:
        for p in summary["recordings"]:
            click.echo(f"wrote {p}")
        click.echo(f"wrote {summary['ground_truth']}/ (room, {summary['frames']} frames, world {summary['world']}, "
                   f"up {summary['up']})")
    else:
        for p in summary["recordings"]:
            click.echo(f"wrote {p}")
        click.echo(f"wrote {summary['ground_truth']}/ ({summary['frames']} frames: {summary['scan_frames']} scan, "
                   f"{summary['after_frames']} after the change; {len(summary['changes'])} change(s))")
