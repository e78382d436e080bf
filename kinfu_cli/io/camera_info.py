"""Camera intrinsics read from a recording's sensor_msgs/CameraInfo."""

from __future__ import annotations

import os
from pathlib import Path

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.messages import camera_info_K
from kinfu_cli.io.recording import open_recording


def intrinsics_from_recording(path: str | os.PathLike) -> dict:
    """fx, fy, cx, cy, width, height from the first sensor_msgs/CameraInfo of a recording (MCAP, ROS 1
    .bag or ROS 2 bag folder, read with the project's recording reader); the depth camera's if several."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording")
    with open_recording(path) as rec:
        topics = rec.topics_of_type("sensor_msgs/msg/CameraInfo")
        if not topics:
            raise RecordingError(f"{path}: no sensor_msgs/CameraInfo topic; intrinsics missing "
                                 "(give fx, fy, cx, cy)")
        topic = ([t for t in topics if "depth" in t] or topics)[0]
        msg = rec.first_message(topic)
        if msg is None:
            raise RecordingError(f"{path}: topic {topic} has no messages; intrinsics missing")
        K, w, h = camera_info_K(msg, f"{path}: {topic}")
    return dict(fx=float(K[0, 0]), fy=float(K[1, 1]), cx=float(K[0, 2]), cy=float(K[1, 2]), width=w, height=h)
