"""Hand trajectories: from a pose topic, from a TF frame, or from a Polhemus `.traj` text file.

`load_hand_trajectory(path)` returns a `Trajectory` (kinfu_cli/io/trajectory.py). From a recording, `t` is in
seconds from the first sample and `t0_ns` is that sample's stamp (header stamps; log time where the header stamp
is zero). Duplicate stamps keep the last sample, so `t` is strictly increasing.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.errors import KinfuError, RecordingError, TrajectoryError
from kinfu_cli.core.poses import quaternion_to_matrix
from kinfu_cli.io.messages import POSE_TYPES, header_frame, header_stamp_ns, pose_message_to_tq
from kinfu_cli.io.polhemus import read_polhemus
from kinfu_cli.io.recording import Recording, open_recording
from kinfu_cli.io.roles import detect_roles
from kinfu_cli.io.tf_buffer import QUAT_NORM2_TOLERANCE, TfBuffer
from kinfu_cli.io.trajectory import Trajectory

TEXT_SUFFIXES = (".traj",)


def load_hand_trajectory(path: str | os.PathLike, hand_topic: str | None = None, hand_frame: str | None = None,
                         world_frame: str | None = None) -> Trajectory:
    """Hand trajectory from a recording (pose topic or TF frame) or a Polhemus `.traj` file.

    hand_topic: a PoseStamped / PoseWithCovarianceStamped / Odometry / TransformStamped topic.
    hand_frame: a TF frame; the trajectory is world_frame <- hand_frame at each stamp of the hand frame's link.
    world_frame: frame to express the trajectory in (a pose topic in another frame is moved through TF, as are the
    samples of one whose frame_id changes mid-stream, said in the recording's problems; without it, those are
    moved into the detected world frame, see _common_frame; an empty frame_id is the frame of the sample before).
    With neither, the hand is detected by name (a pose topic named hand/wrist/tracker, or a TF frame named hand).
    """
    path = Path(path)
    if path.suffix.lower() in TEXT_SUFFIXES:
        return read_polhemus(path)
    if path.is_dir() and not (path / "metadata.yaml").exists():
        text = next((p for s in TEXT_SUFFIXES for p in path.rglob(f"*{s}")), None)
        if text is not None:  # a data set folder, which the ROS 2 reader would refuse as "no metadata.yaml"
            raise TrajectoryError(f"{path}: a folder of trajectory files (such as {text.relative_to(path)}), not a "
                                  f"recording; give one of its files (or score the folder with the evaluation)")
    with open_recording(path) as rec:
        traj = hand_trajectory_from_recording(rec, hand_topic, hand_frame, world_frame)
        if rec.problems:  # a recording cut short: what was lost goes with the trajectory
            traj.meta["recording_problems"] = list(rec.problems)
        traj.meta["recording_span_ns"] = (rec.start_ns, rec.end_ns)  # to place the hand's stamps in the recording
        return traj


def hand_trajectory_from_recording(rec: Recording, hand_topic: str | None = None, hand_frame: str | None = None,
                                   world_frame: str | None = None) -> Trajectory:
    """As load_hand_trajectory, on an open Recording."""
    tf: TfBuffer | None = None
    if hand_topic is None and hand_frame is None:
        tf = TfBuffer.from_recording(rec)
        roles = detect_roles(rec, world_frame=world_frame or "", tf=tf)
        hand_topic, hand_frame = roles.hand_topic, roles.hand_frame
        if hand_topic is None and hand_frame is None:
            poses = ", ".join(rec.topics_of_type(*POSE_TYPES)) or "none"
            raise RecordingError(f"{rec.path}: no hand pose topic or TF frame found; pose topics: {poses}",
                                 parameter="hand_topic/hand_frame")
    if hand_topic is not None:
        return _from_topic(rec, hand_topic, world_frame, tf)
    return _from_tf(rec, hand_frame, world_frame, tf)


def _finish(stamps: np.ndarray, T: np.ndarray, frame: str, source: str, meta: dict) -> Trajectory:
    if stamps.shape[0] == 0:
        raise TrajectoryError(f"{source}: no samples")
    order = np.argsort(stamps, kind="stable")
    stamps, T = stamps[order], T[order]
    keep = np.ones(stamps.shape[0], bool)
    keep[:-1] = stamps[1:] != stamps[:-1]
    meta = dict(meta, duplicates_dropped=int((~keep).sum()))
    stamps, T = stamps[keep], T[keep]
    t0 = int(stamps[0])
    traj = Trajectory(t=(stamps - t0) * 1e-9, positions=T[:, :3, 3], rotations=T[:, :3, :3], frame=frame,
                      source=source, t0_ns=t0, meta=meta)
    return traj.validate(min_samples=1)


def _from_topic(rec: Recording, topic: str, world_frame: str | None, tf: TfBuffer | None) -> Trajectory:
    info = rec.require_topic(topic, "hand topic")
    if not set(POSE_TYPES) & set(info.msgtypes):
        raise RecordingError(f"{rec.path}: hand topic {topic} carries {info.msgtype}, expected one of "
                             f"{', '.join(POSE_TYPES)}")
    stamps, trans, quats, frames = [], [], [], []
    for _, msgtype, log_ns, msg in rec.typed_messages([topic]):
        if msgtype not in POSE_TYPES:
            continue
        s = header_stamp_ns(msg)
        stamps.append(s if s is not None else log_ns)
        t, q = pose_message_to_tq(msg, msgtype)
        trans.append(t)
        quats.append(q)
        frames.append(header_frame(msg).lstrip("/"))
    empty = sum(not f for f in frames)
    frames = _fill_empty_frames(frames)
    frame = frames[0] if frames else ""
    if empty and len(set(frames) - {""}) > 1:  # which frame those samples were in is a guess: say it
        rec.problems.append(f"{rec.path}: hand topic {topic}: {empty} samples without frame_id were taken in the "
                            f"frame of the sample before them")
    source = f"{rec.path}:{topic}"
    stamps_a = np.asarray(stamps, dtype=np.int64)
    T = np.zeros((len(stamps), 4, 4))
    if stamps:
        q = np.asarray(quats, dtype=np.float64)
        n2 = np.einsum("ij,ij->i", q, q)
        bad = np.flatnonzero(~(np.abs(n2 - 1.0) < QUAT_NORM2_TOLERANCE))  # NaN too
        if bad.size:
            raise TrajectoryError(f"{source}: sample {int(bad[0])} has the orientation quaternion "
                                  f"{q[bad[0]].tolist()}, expected unit length (as tf2 requires)")
        T[:, :3, :3] = quaternion_to_matrix(q)
        T[:, :3, 3] = np.asarray(trans, dtype=np.float64)
        T[:, 3, 3] = 1.0
    meta = {"topic": topic, "msgtype": info.msgtype}
    if len(set(frames) - {""}) > 1:  # the poses of one topic in several frames: moved into one through TF
        tf = tf if tf is not None else TfBuffer.from_recording(rec)
        target = world_frame or _common_frame(rec, topic, frames, tf)
        stamps_a, T, frame = _into_one_frame(rec, topic, source, stamps_a, T, frames, target, tf, meta)
    if world_frame and frame and world_frame != frame:
        tf = tf if tf is not None else TfBuffer.from_recording(rec)
        rng = tf.time_range(world_frame, frame)
        if rng is not None:  # samples where no chain with transforms reaches the world cannot be moved
            ok = tf.covers(world_frame, frame, stamps_a)
            meta["outside_tf_range"] = int((~ok).sum())
            if not ok.any():
                raise TrajectoryError(f"{source}: no sample lies within the TF range of {world_frame} <- {frame} "
                                      f"[{rng[0] * 1e-9:.3f}, {rng[1] * 1e-9:.3f}] s")
            stamps_a, T = stamps_a[ok], T[ok]
        T = tf.lookup_many(world_frame, frame, stamps_a) @ T
        meta["moved_from_frame"] = frame
        frame = world_frame
    return _finish(stamps_a, T, frame or (world_frame or ""), source, meta)


def _fill_empty_frames(frames: list[str]) -> list[str]:
    """An empty frame_id (a driver that sometimes leaves it out) is the frame of the sample before it; leading
    empty ones the first non-empty frame_id."""
    last = next((f for f in frames if f), "")
    filled = []
    for f in frames:
        last = f or last
        filled.append(last)
    return filled


def _common_frame(rec: Recording, topic: str, frames: list[str], tf: TfBuffer) -> str:
    """The frame to bring the samples of a topic in several frames into when no world frame is given: the world
    frame detection picks (as the commands would), when TF links it to every frame_id; else a frame_id that is a
    TF root or hangs from its root by static links only (a moving link such as an arm's would make the hand move
    with the arm); else the first frame_id."""
    names = list(dict.fromkeys(f for f in frames if f))
    try:
        world = detect_roles(rec, hand_topic=topic, tf=tf).world_frame
    except KinfuError:  # a camera whose TF chain is broken: no detected world to go by
        world = None
    if world and all(f == world or tf.connected(world, f) for f in names):
        return world
    tree = tf.tree()
    fixed = [f for f in names if all(tf.is_static(c) for c in chain_up(tree, f, None))]
    return fixed[0] if fixed else names[0]


def _into_one_frame(rec: Recording, topic: str, source: str, stamps: np.ndarray, T: np.ndarray, frames: list[str],
                    target: str, tf: TfBuffer, meta: dict) -> tuple[np.ndarray, np.ndarray, str]:
    """(stamps, T, target) of a pose topic whose frame_id changes mid-stream: each sample in another frame than
    `target` moved into it through TF (those outside the TF range dropped, counted in meta), said in the
    recording's problems; TrajectoryError when no TF chain links the frames (the positions cannot be mixed)."""
    frames_a = np.asarray(frames, dtype=object)
    first = next(f for f in frames if f)
    change = next(i for i, f in enumerate(frames) if f and f != first)
    said = (f"hand topic {topic} changes frame_id from {first!r} to {frames[change]!r} at stamp "
            f"{int(stamps[change])} ns")
    keep = np.ones(stamps.shape[0], bool)
    moved = 0
    for f in sorted(set(frames) - {"", target}):
        if not tf.connected(target, f):
            raise TrajectoryError(f"{source}: {said}, and no TF chain links {target!r} and {f!r}: the positions "
                                  f"cannot be brought into one frame; expected one frame_id")
        in_f = frames_a == f
        movable = in_f.copy()
        if tf.time_range(target, f) is not None:  # samples outside the TF range of the chain cannot be moved
            movable &= tf.covers(target, f, stamps)
            keep &= ~(in_f & ~movable)
        if movable.any():
            T[movable] = tf.lookup_many(target, f, stamps[movable]) @ T[movable]
        moved += int(movable.sum())
    lost = int((~keep).sum())
    meta["frame_ids"] = sorted(set(frames) - {""})
    meta["outside_tf_range"] = meta.get("outside_tf_range", 0) + lost
    rec.problems.append(f"{rec.path}: {said}: its {moved} samples in other frames than {target!r} were moved into "
                        f"it through TF" + (f" ({lost} outside the TF range left out)" if lost else ""))
    return stamps[keep], T[keep], target


def _from_tf(rec: Recording, hand_frame: str, world_frame: str | None, tf: TfBuffer | None) -> Trajectory:
    tf = tf if tf is not None else TfBuffer.from_recording(rec)
    hand_frame = hand_frame.lstrip("/")
    if hand_frame not in tf.frames():
        avail = ", ".join(tf.frames()) or "none"
        raise RecordingError(f"{rec.path}: hand frame {hand_frame!r} is not in the TF tree (frames: {avail})")
    tree = tf.tree()
    if hand_frame not in tree:
        raise RecordingError(f"{rec.path}: hand frame {hand_frame!r} is a TF root; expected a frame with a parent")
    if not world_frame:
        chain = chain_up(tree, hand_frame, None)
        roots = [tree[chain[-1]]] if chain else []
        world_frame = next((f for f in ("world", "map", "odom") if f in chain + roots), (chain + roots)[-1])
    # sample at the stamps of the closest moving link on the way up (the hand's own link unless it is static)
    moving = next((f for f in chain_up(tree, hand_frame, world_frame) if not tf.is_static(f)), None)
    if moving is None:
        raise TrajectoryError(f"{rec.path}: every TF link from {world_frame} to {hand_frame} is static; a hand "
                              f"trajectory needs a moving frame")
    stamps = tf.link_stamps(moving)
    if tf.time_range(world_frame, hand_frame) is not None:  # other moving links on the chain may cover less time
        stamps = stamps[tf.covers(world_frame, hand_frame, stamps)]
    T = tf.lookup_many(world_frame, hand_frame, stamps) if stamps.size else np.zeros((0, 4, 4))
    source = f"{rec.path}:tf {world_frame}<-{hand_frame}"
    return _finish(stamps, T, world_frame, source, {"hand_frame": hand_frame})


def chain_up(tree: dict[str, str], frame: str, stop: str | None) -> list[str]:
    """Frames from `frame` up to (not including) `stop` or the root; each has a link to its parent."""
    out = []
    while frame in tree and frame != stop and frame not in out:
        out.append(frame)
        frame = tree[frame]
    return out
