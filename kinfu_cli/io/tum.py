"""Camera trajectories as TUM RGB-D text files: `timestamp tx ty tz qx qy qz qw`, one pose a line.

The format `evo_ape tum gt.tum est.tum` and the TUM benchmark tools read: the timestamp in seconds (here
the recording's stamps, so a fused trajectory and the recording's own poses line up), the camera position
in metres and its orientation as a unit quaternion (x, y, z, w), camera-to-world. Lines starting with `#`
are comments.
"""

from __future__ import annotations

import os
from decimal import Decimal
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.errors import ConfigError, RecordingError, TrajectoryError
from kinfu_cli.core.poses import check_poses, matrix_to_quaternion, quaternion_to_matrix
from kinfu_cli.core.progress import progress
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.hand import hand_trajectory_from_recording
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles

HEADER = "# timestamp tx ty tz qx qy qz qw"


def tum_lines(stamps_ns, poses) -> list[str]:
    """The TUM lines of (N,) integer nanosecond stamps and (N, 4, 4) camera-to-world poses (N may be 0)."""
    stamps = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
    if stamps.size == 0:
        return []
    T = check_poses(poses, "poses")
    if len(T) != len(stamps):
        raise TrajectoryError(f"{len(stamps)} stamps for {len(T)} poses")
    q = matrix_to_quaternion(T[:, :3, :3])
    t = T[:, :3, 3]
    # seconds with nanosecond digits, written from the integer stamp (a float64 of 1.7e9 s keeps ~0.2 us only)
    secs = [f"{s // 1_000_000_000}.{s % 1_000_000_000:09d}" if s >= 0 else f"{s * 1e-9:.9f}" for s in stamps.tolist()]
    return [f"{s} " + " ".join(f"{v:.9f}" for v in (*p, *r)) for s, p, r in zip(secs, t, q)]


def write_tum(path: str | os.PathLike, stamps_ns, poses, comment: str = "") -> Path:
    """Write a TUM trajectory file atomically (a header comment, then one line per pose)."""
    lines = [HEADER] + [f"# {c}" for c in comment.splitlines() if c] + tum_lines(stamps_ns, poses)
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return path


def read_tum(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(N,) integer nanosecond stamps (parsed exactly from the text) and (N, 4, 4) camera-to-world poses of a
    TUM trajectory file; TrajectoryError naming the file and line for anything that is not 8 numbers or a
    comment."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise TrajectoryError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or 'not text'})") from None
    stamps, rows = [], []
    for n, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        tokens = line.replace(",", " ").split()
        try:
            vals = [float(v) for v in tokens]
            stamp = int(Decimal(tokens[0]) * 1_000_000_000) if len(tokens) == 8 else 0
        except (ValueError, ArithmeticError):
            vals = []
        if len(vals) != 8 or not np.all(np.isfinite(vals)) or not np.linalg.norm(vals[4:]) > 1e-9:
            raise TrajectoryError(f"{path}:{n}: expected 8 finite numbers 'timestamp tx ty tz qx qy qz qw' (a "
                                  f"non-zero quaternion), got {line[:60]!r}")
        if not -(2**63) <= stamp < 2**63:  # int64 nanoseconds: +-292 years around 1970
            raise TrajectoryError(f"{path}:{n}: timestamp {tokens[0]} s is beyond the +-{2**63 // 10**9} s "
                                  f"(years 1678-2262) that nanosecond stamps hold")
        stamps.append(stamp)
        rows.append(vals)
    data = np.array(rows, dtype=np.float64).reshape(-1, 8)
    T = np.tile(np.eye(4), (len(data), 1, 1))
    if len(data):
        T[:, :3, :3] = quaternion_to_matrix(data[:, 4:8])
        T[:, :3, 3] = data[:, 1:4]
    return np.array(stamps, dtype=np.int64), T


def recording_trajectory(recording: str | os.PathLike, roles_kw: dict | None = None, pose_source: str = "tf",
                         pose_topic: str | None = None, tolerance_s: float = 0.05, start_s: float | None = None,
                         end_s: float | None = None, every: int = 1, quiet: bool = True
                         ) -> tuple[np.ndarray, np.ndarray, dict]:
    """The recording's own camera poses (TF world <- camera, or a pose topic) at the stamp of every depth frame
    `kinfu fuse` would assemble with the same options: (N,) stamps ns, (N, 4, 4) poses, the frame statistics.
    The ground truth that a fused trajectory.tum is compared with. The summary's warnings say what was lost (a
    recording cut short) or assumed."""
    if pose_source == "none":
        raise ConfigError("a trajectory needs camera poses: 'tf' or 'topic'", parameter="pose_source")
    stats = FrameStats()
    stamps, poses = [], []
    with open_recording(recording) as rec:
        roles = detect_roles(rec, **(roles_kw or {}))
        if roles.depth_topic is None:  # a pose-only recording (evo's data, a robot's odometry): its own samples
            return _pose_stream(rec, roles, pose_source, pose_topic, start_s, end_s, every,
                                (roles_kw or {}).get("world_frame"))
        total = rec.topics[roles.depth_topic].count if roles.depth_topic in rec.topics else None
        frames = iter_frames(rec, roles, pose_source=pose_source, pose_topic=pose_topic, tolerance_s=tolerance_s,
                             start_s=start_s, end_s=end_s, every=every, stats=stats)
        for f in progress(frames, total=total, desc="trajectory", quiet=quiet, unit="frame"):
            if f.T_world_camera is not None:
                stamps.append(f.stamp_ns)
                poses.append(f.T_world_camera)
        if not stamps:
            raise RecordingError(f"{rec.path}: no depth frame with a camera pose (dropped: {stats.dropped or 'none'}, "
                                 f"depth messages: {stats.depth_messages})")
        summary = {"recording": str(rec.path), "roles": roles.as_dict(), "stats": stats.as_dict(),
                   "world_frame": roles.world_frame if pose_source == "tf" else pose_topic,
                   "warnings": rec.problems + [f"{rec.path}: {n}" for n in stats.notes], "sampled_at": "depth frames"}
    return np.array(stamps, dtype=np.int64), np.array(poses), summary


def _pose_stream(rec, roles, pose_source: str, pose_topic: str | None, start_s: float | None, end_s: float | None,
                 every: int, world_frame: str | None) -> tuple[np.ndarray, np.ndarray, dict]:
    """The poses of a recording without depth at their own samples: the pose topic's messages (in their own
    frame unless `world_frame` is given), or the TF link world <- camera frame at each of its stamps (the camera
    frame must be given: no depth image names it)."""
    if pose_source == "topic":
        traj = hand_trajectory_from_recording(rec, hand_topic=pose_topic, world_frame=world_frame)
        what = f"pose topic {pose_topic}"
    else:
        if roles.camera_frame is None:
            raise RecordingError(f"{rec.path}: no depth topic to take the camera frame from; give the TF frame whose "
                                 f"poses to write, or a pose topic", parameter="camera_frame")
        traj = hand_trajectory_from_recording(rec, hand_frame=roles.camera_frame, world_frame=roles.world_frame)
        what = f"TF {traj.frame} <- {roles.camera_frame}"
    stamps = traj.t0_ns + np.round(traj.t * 1e9).astype(np.int64)
    rel = (stamps - (rec.start_ns or 0)) * 1e-9
    if (start_s is not None or end_s is not None) and not (-1.0 <= rel[0] and rel[-1] <= rec.duration_s + 1.0):
        raise ConfigError(f"{rec.path}: the {what} stamps run on another clock than the recording (sim time?), so "
                          f"a window in seconds from the recording start does not apply to them", parameter="start_s")
    keep = np.ones(len(stamps), dtype=bool)
    if start_s is not None:
        keep &= rel >= start_s
    if end_s is not None:
        keep &= rel <= end_s
    idx = np.flatnonzero(keep)[::every]
    if not idx.size:
        raise RecordingError(f"{rec.path}: no {what} sample in the selected window")
    T = np.tile(np.eye(4), (len(idx), 1, 1))
    T[:, :3, :3] = traj.rotations[idx] if traj.rotations is not None else np.eye(3)
    T[:, :3, 3] = traj.positions[idx]
    summary = {"recording": str(rec.path), "roles": roles.as_dict(), "stats": {"depth_messages": 0,
               "pose_samples": int(len(stamps)), "used": int(len(idx))}, "world_frame": traj.frame,
               "warnings": list(rec.problems), "sampled_at": f"the samples of {what} (no depth topic)"}
    return stamps[idx], T, summary


def fused_trajectory(folder: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory a `kinfu fuse` output folder holds (its trajectory.tum): (N,) stamps ns, (N, 4, 4) poses."""
    folder = Path(folder)
    path = folder / "trajectory.tum"
    if not path.is_file():
        what = "a fuse output folder from an older kinfu" if (folder / "report.json").is_file() else "not a fuse output"
        raise TrajectoryError(f"{folder}: has no trajectory.tum ({what}; run kinfu fuse again)")
    return read_tum(path)
