"""`kinfu synth`: a synthetic tabletop recording (MCAP, ROS 1 bag, ROS 2 bag) with its ground truth."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinfu_cli.core.errors import ConfigError

FORMAT_NAMES = {"mcap": "recording.mcap", "bag": "recording.bag", "ros2": "recording_ros2"}


def parse_formats(text: str) -> list[str]:
    """'mcap,bag,ros2' -> ['mcap', 'bag', 'ros2'] (ConfigError naming --formats for anything else)."""
    items = [t.strip().lower() for t in text.split(",") if t.strip()]
    bad = [t for t in items if t not in FORMAT_NAMES]
    if not items or bad:
        raise ConfigError(f"--formats {text!r}: expected a comma-separated subset of mcap,bag,ros2")
    return list(dict.fromkeys(items))


def run_synth(out: str | Path, seed: int = 0, width: int = 320, height: int = 240, frames: int = 36,
              formats: list[str] = ("mcap", "bag", "ros2"), scenario: str = "pick-and-place", n_objects: int = 4,
              hand_rate: float = 100.0, frame_rate: float = 5.0, noise: bool = True, depth_format: str = "png",
              color_format: str = "jpeg", jpeg_quality: int = 75, quiet: bool = True,
              camera_pose_topic: str | None = None) -> dict:
    """Build the scenario and write the containers and OUT/ground_truth/. Returns a summary (paths, counts).
    camera_pose_topic: also write the true camera poses (PoseStamped in `world`) on this topic."""
    from kinfu_cli.sim.scenario import (check_camera_pose_topic, make_scenario, recording_topics, write_ground_truth,
                                        write_recordings)

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"-o {out}: exists and is not a folder")
    check_camera_pose_topic(camera_pose_topic, depth_format, color_format)
    sc = make_scenario(seed=seed, kind=scenario, width=width, height=height, frames=frames, n_objects=n_objects,
                       noise=noise, hand_rate_hz=hand_rate, frame_rate_hz=frame_rate)
    paths = [out / FORMAT_NAMES[f] for f in formats]
    write_recordings(sc, paths, depth_format=depth_format, color_format=color_format, quiet=quiet,
                     jpeg_quality=jpeg_quality, camera_pose_topic=camera_pose_topic)
    gt = write_ground_truth(sc, out / "ground_truth",
                            topics=recording_topics(depth_format, color_format, camera_pose_topic))
    for p in paths + [gt]:
        _relax_permissions(p)
    return {"recordings": [str(p) for p in paths], "ground_truth": str(gt), "frames": len(sc.frames),
            "scan_frames": sc.meta["n_scan"], "after_frames": sc.meta["n_after"], "hand_samples": len(sc.hand),
            "changes": sc.changes, "seed": seed, "scenario": scenario, "width": width, "height": height,
            "camera_pose_topic": camera_pose_topic}


def _relax_permissions(path: Path) -> None:
    """The atomic temp files/folders are created 0600/0700: give outputs the usual umask-based modes."""
    import os

    umask = os.umask(0)
    os.umask(umask)
    paths = [path] + (sorted(path.rglob("*")) if path.is_dir() else [])
    for p in paths:
        os.chmod(p, (0o777 if p.is_dir() else 0o666) & ~umask)


@click.command("synth", short_help="Write a synthetic tabletop recording (MCAP, bag, ROS 2) with ground truth.")
@click.option("-o", "--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder (gets recording.mcap, recording.bag, recording_ros2/, ground_truth/).")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of the scene, camera path, hand and noise.")
@click.option("--width", default=320, show_default=True, type=int, help="Depth/colour image width (pixels).")
@click.option("--height", default=240, show_default=True, type=int, help="Depth/colour image height (pixels).")
@click.option("--frames", default=36, show_default=True, type=int,
              help="Depth frames in all: 2/3 initial scan, 1/3 after the change.")
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
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def command(out, seed, width, height, frames, formats, scenario, n_objects, hand_rate, frame_rate, noise,
            depth_format, color_format, jpeg_quality, camera_pose_topic, as_json, quiet):
    """Write a synthetic tabletop recording and its ground truth.

    A table with boxes, cylinders, spheres and meshes; a 6-joint arm carries a Kinect-like camera (TF chain
    world -> base_link -> link1..link6 -> wrist -> camera_optical) over an arc for the initial scan; a hand
    (/hand/pose, PoseStamped in world) places, removes or picks-and-places an object; then views of the change.
    Depth is ray cast with open3d plus the Kinect v1 noise model (Nguyen et al. 2012), stored as 16UC1 mm
    (compressedDepth PNG by default). OUT/ground_truth/ holds scene_before.ply, scene_after.ply,
    objects/<id>.ply (+ table.ply, floor.ply), changes.json, camera_poses.txt and hand.traj. Seeded and
    deterministic. With --camera-pose-topic TOPIC the recordings also carry the true camera poses as
    geometry_msgs/PoseStamped (frame world) at every depth frame stamp, for `kinfu fuse --pose topic`.

    \b
    Example:
      kinfu synth -o sample_data/tabletop
      kinfu synth -o /tmp/small --width 64 --height 48 --frames 6 --formats mcap --scenario place
      kinfu synth -o /tmp/posed --camera-pose-topic /camera/pose
    """
    if frames < 2:
        raise ConfigError(f"--frames {frames}: expected at least 2 (scan and after the change)")
    if width < 8 or height < 6:
        raise ConfigError(f"--width/--height {width}x{height}: expected at least 8x6 pixels")
    if not 0 <= n_objects <= 12:
        raise ConfigError(f"--n-objects {n_objects}: expected 0..12")
    if not hand_rate > 0:
        raise ConfigError(f"--hand-rate {hand_rate}: expected a positive rate in Hz")
    if not frame_rate > 0:
        raise ConfigError(f"--frame-rate {frame_rate}: expected a positive rate in Hz")
    if not 1 <= jpeg_quality <= 100:
        raise ConfigError(f"--jpeg-quality {jpeg_quality}: expected 1..100")
    summary = run_synth(out, seed=seed, width=width, height=height, frames=frames, formats=parse_formats(formats),
                        scenario=scenario, n_objects=n_objects, hand_rate=hand_rate, frame_rate=frame_rate,
                        noise=noise, depth_format=depth_format, color_format=color_format,
                        jpeg_quality=jpeg_quality, quiet=quiet, camera_pose_topic=camera_pose_topic)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        for p in summary["recordings"]:
            click.echo(f"wrote {p}")
        click.echo(f"wrote {summary['ground_truth']}/ ({summary['frames']} frames: {summary['scan_frames']} scan, "
                   f"{summary['after_frames']} after the change; {len(summary['changes'])} change(s))")
