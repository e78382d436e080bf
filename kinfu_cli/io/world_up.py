"""The up direction a recording declares for its world frame (topic `/kinfu/world_up`).

REP-103 makes the fixed frames of a ROS robot (world, map, odom, ...) z-up, but recordings converted from
frame folders (`import_folder`) call the data set's own frame `world` although it is often the first
camera (y down) or some other convention. Such a recording says so on WORLD_UP_TOPIC: one
geometry_msgs/Vector3Stamped whose header.frame_id is the world frame and whose vector is the unit up
direction (against gravity) in it, or the zero vector when the up direction is not known (the frame does
not follow REP-103, so the name alone says nothing). Any recorder may write it; recordings without it are
taken by their frame names.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.messages import header_frame

WORLD_UP_TOPIC = "/kinfu/world_up"
WORLD_UP_TYPE = "geometry_msgs/msg/Vector3Stamped"


@dataclass(frozen=True)
class WorldUp:
    """What a recording declares: its world frame and that frame's unit up direction (None: not known)."""

    frame: str
    up: np.ndarray | None


def read_world_up(rec) -> WorldUp | None:
    """The declaration on WORLD_UP_TOPIC of an open Recording, or None when it has no such topic;
    RecordingError when the message is not a finite vector."""
    info = rec.topics.get(WORLD_UP_TOPIC)
    if info is None or info.count == 0:
        return None
    msg = rec.first_message(WORLD_UP_TOPIC)
    if msg is None:
        return None
    try:
        v = np.array([float(msg.vector.x), float(msg.vector.y), float(msg.vector.z)])
    except (AttributeError, TypeError, ValueError):
        raise RecordingError(f"{rec.path}: {WORLD_UP_TOPIC} is not a {WORLD_UP_TYPE}") from None
    n = float(np.linalg.norm(v))
    if not np.all(np.isfinite(v)):
        raise RecordingError(f"{rec.path}: {WORLD_UP_TOPIC} holds a non-finite vector {v.tolist()}")
    return WorldUp(header_frame(msg).lstrip("/"), v / n if n > 1e-9 else None)
