"""The synthetic recording pipeline: one seeded scenario written into several containers plus its ground truth.

`synthesize(out, ...)` checks every argument before writing anything, builds the scenario
(`sim.scenario.make_scenario`), streams it into OUT/recording.mcap, OUT/recording.bag and/or OUT/recording_ros2/
at once and writes OUT/ground_truth/. It returns a `SynthResult`, whose `to_json()` is the summary `kinfu synth`
prints as JSON.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from kinfu_cli.core.atomic import atomic_dir
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.room import WORLDS, RoomScenario, make_room, write_room_ground_truth, write_room_recordings
from kinfu_cli.sim.scenario import (MAX_FRAME_RATE_HZ, MAX_HAND_RATE_HZ, MIN_FRAME_RATE_HZ, MIN_HAND_RATE_HZ,
                                    Scenario, check_camera_pose_topic, make_scenario, recording_topics,
                                    write_ground_truth, write_recordings)

SCENES = ("tabletop", "room", "objects", "household")  # objects / household: the tabletop scenario on
# `sim.scene.segmentation_scene` / `sim.household.household_scene`
FORMAT_NAMES = {"mcap": "recording.mcap", "bag": "recording.bag", "ros2": "recording_ros2"}


@dataclass
class SynthResult:
    """What `synthesize` wrote: the containers, the ground-truth folder, and the scenario they hold."""

    recordings: list[Path]
    ground_truth: Path
    scenario: Scenario | RoomScenario
    camera_pose_topic: str | None = None

    def to_json(self) -> dict:
        sc = self.scenario
        if isinstance(sc, RoomScenario):
            lo, hi = sc.bounds()
            return {"recordings": [str(p) for p in self.recordings], "ground_truth": str(self.ground_truth),
                    "frames": len(sc.frames), "scene": "room", "world": sc.world, "up": sc.up.tolist(),
                    "room_bounds": [lo.tolist(), hi.tolist()], "seed": sc.seed, "width": sc.width,
                    "height": sc.height, "camera_pose_topic": self.camera_pose_topic}
        return {"recordings": [str(p) for p in self.recordings], "ground_truth": str(self.ground_truth),
                "frames": len(sc.frames), "scan_frames": sc.meta["n_scan"], "after_frames": sc.meta["n_after"],
                "hand_samples": len(sc.hand), "changes": sc.changes, "seed": sc.seed, "scenario": sc.kind,
                "width": sc.width, "height": sc.height, "camera_pose_topic": self.camera_pose_topic,
                **({"scene": sc.meta["layout"]} if sc.meta.get("layout") else {})}


def synthesize(out: str | os.PathLike, seed: int = 0, width: int = 320, height: int = 240, frames: int = 36,
               formats: tuple[str, ...] = ("mcap", "bag", "ros2"), scenario: str = "pick-and-place",
               n_objects: int = 4, hand_rate: float = 100.0, frame_rate: float = 5.0, noise: bool = True,
               depth_format: str = "png", color_format: str = "jpeg", jpeg_quality: int = 75, quiet: bool = True,
               camera_pose_topic: str | None = None, scene: str = "tabletop", world: str = "z-up",
               force: bool = False) -> SynthResult:
    """Build the scenario and write the containers named in `formats` (FORMAT_NAMES) and OUT/ground_truth/.
    force: an entry of an earlier result at `out` with a new file's name, edited since kinfu wrote it, is replaced.
    camera_pose_topic: also write the true camera poses (PoseStamped in `world`) on this topic; quiet: no
    progress bar. scene: "tabletop" (the arm scenario) or "room" (`sim.room`: a handheld camera walking through a
    furnished room; `scenario`, `n_objects` and `hand_rate` do not apply) or "objects" (the tabletop scenario on the
    segmentation ground-truth scene `sim.scene.segmentation_scene`; `n_objects` does not apply) or "household" (the
    same on `sim.household.household_scene`: 5-11 YCB-like objects made of parts); world: "z-up" or
    "y-down" (room only)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out} exists and is not a folder", parameter="out")
    if not formats or any(f not in FORMAT_NAMES for f in formats):
        raise ConfigError(f"expected some of {', '.join(FORMAT_NAMES)}, got {', '.join(formats) or 'none'}",
                          parameter="formats")
    check_number(hand_rate, "hand_rate", MIN_HAND_RATE_HZ, MAX_HAND_RATE_HZ, unit="Hz")
    check_number(frame_rate, "frame_rate", MIN_FRAME_RATE_HZ, MAX_FRAME_RATE_HZ, unit="Hz")
    check_number(seed, "seed", 0, 2 ** 63 - 1, integer=True)  # numpy refuses negative seeds with a bare ValueError
    if not 1 <= jpeg_quality <= 100:
        raise ConfigError(f"expected 1..100, got {jpeg_quality}", parameter="jpeg_quality")
    check_camera_pose_topic(camera_pose_topic, depth_format, color_format)
    if scene not in SCENES:
        raise ConfigError(f"expected one of {', '.join(SCENES)}, got {scene!r}", parameter="scene")
    if world not in WORLDS:
        raise ConfigError(f"expected one of {', '.join(WORLDS)}, got {world!r}", parameter="world")
    if scene != "room" and world != "z-up":
        raise ConfigError(f"the tabletop scene is z-up only, got {world!r}; the room scene takes either world",
                          parameter="world")
    # one transaction: a failed or interrupted run leaves no folder (nor an empty one that blocks the rerun), and
    # a rerun replaces the whole earlier result instead of mixing old and new files (what other commands wrote
    # there, such as pois.json or a fuse/ folder beside the recording, stays)
    with atomic_dir(out, own=(*FORMAT_NAMES.values(), "ground_truth"), force=force) as tmp:
        result = _write(tmp, seed=seed, width=width, height=height, frames=frames, formats=formats,
                        scenario=scenario, n_objects=n_objects, hand_rate=hand_rate, frame_rate=frame_rate,
                        noise=noise, depth_format=depth_format, color_format=color_format, jpeg_quality=jpeg_quality,
                        quiet=quiet, camera_pose_topic=camera_pose_topic, scene=scene, world=world)
    result.recordings = [out / p.name for p in result.recordings]
    result.ground_truth = out / result.ground_truth.name
    return result


def _write(out: Path, *, seed, width, height, frames, formats, scenario, n_objects, hand_rate, frame_rate, noise,
           depth_format, color_format, jpeg_quality, quiet, camera_pose_topic, scene, world) -> SynthResult:
    """synthesize's writing, into the folder `out` (its temporary folder)."""
    if scene == "room":
        room = make_room(seed=seed, world=world, width=width, height=height, frames=frames, noise=noise,
                         frame_rate_hz=frame_rate)
        paths = [out / FORMAT_NAMES[f] for f in formats]
        topics = recording_topics(depth_format, color_format, camera_pose_topic)
        topics.pop("hand")
        topics.pop("tf_static")
        write_room_recordings(room, paths, topics, depth_format=depth_format, color_format=color_format,
                              quiet=quiet, jpeg_quality=jpeg_quality, camera_pose_topic=camera_pose_topic)
        gt = write_room_ground_truth(room, out / "ground_truth", topics)
        for p in paths + [gt]:
            _relax_permissions(p)
        return SynthResult(paths, gt, room, camera_pose_topic)
    sc = make_scenario(seed=seed, kind=scenario, width=width, height=height, frames=frames, n_objects=n_objects,
                       noise=noise, hand_rate_hz=hand_rate, frame_rate_hz=frame_rate,
                       layout=scene if scene in ("objects", "household") else "tabletop")
    paths = [out / FORMAT_NAMES[f] for f in formats]
    write_recordings(sc, paths, depth_format=depth_format, color_format=color_format, quiet=quiet,
                     jpeg_quality=jpeg_quality, camera_pose_topic=camera_pose_topic)
    gt = write_ground_truth(sc, out / "ground_truth",
                            topics=recording_topics(depth_format, color_format, camera_pose_topic))
    for p in paths + [gt]:
        _relax_permissions(p)
    return SynthResult(paths, gt, sc, camera_pose_topic)


def _relax_permissions(path: Path) -> None:
    """The atomic temp files/folders are created 0600/0700: give outputs the usual umask-based modes."""
    umask = os.umask(0)
    os.umask(umask)
    paths = [path] + (sorted(path.rglob("*")) if path.is_dir() else [])
    for p in paths:
        os.chmod(p, (0o777 if p.is_dir() else 0o666) & ~umask)
