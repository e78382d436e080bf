"""One viewer file from several: the viewer files the stages of one recording wrote (`kinfu batch` viz).

Every message of every part is kept, decoded and re-encoded with Foxglove's official classes (so the file holds
the official schemas once each), with two adjustments that make the parts one scene:
- content a part stamped at 0 (nbv and segment have no clock of their own) is stamped at the reference time of
  the others (the first camera stamp of fuse, else the hand trajectory's start), inside the messages too, so a
  player shows it from the start instead of stretching the timeline back to 1970;
- the occupied-voxel cloud an nbv part draws when it has no mesh is dropped when a part has the fused mesh or
  cloud (as `write_viewer` does when given both).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import foxglove_schemas_protobuf.CameraCalibration_pb2 as cal_pb2
import foxglove_schemas_protobuf.FrameTransform_pb2 as tf_pb2
import foxglove_schemas_protobuf.PointCloud_pb2 as pc_pb2
import foxglove_schemas_protobuf.PosesInFrame_pb2 as pif_pb2
import foxglove_schemas_protobuf.SceneUpdate_pb2 as su_pb2

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.report.viewer_messages import stamp

_CLASSES = {m.DESCRIPTOR.full_name: m for m in (cal_pb2.CameraCalibration, tf_pb2.FrameTransform, pc_pb2.PointCloud,
                                               pif_pb2.PosesInFrame, su_pb2.SceneUpdate)}
_SURFACE = ("/kinfu/mesh", "/kinfu/cloud")


def _read(path: Path) -> list[tuple[str, object, int]]:
    """(topic, official message, log time) of every message of a viewer file."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    out = []
    try:
        with open(path, "rb") as fh:
            for schema, channel, message in make_reader(fh).iter_messages(log_time_order=True):
                cls = _CLASSES.get(schema.name if schema is not None else "")
                if cls is None:
                    raise ConfigError(f"{path}: schema {schema.name if schema else None!r} is not one kinfu writes")
                out.append((channel.topic, cls.FromString(message.data), int(message.log_time)))
    except (OSError, McapError, ValueError) as exc:
        raise ConfigError(f"{path}: not a readable viewer file ({' '.join(str(exc).split())})") from None
    return out


def _restamp(msg, ns: int) -> None:
    """Set the message's own timestamps (the message's, or each scene entity's) to `ns`."""
    if isinstance(msg, su_pb2.SceneUpdate):
        for e in msg.entities:
            e.timestamp.CopyFrom(stamp(ns))
    elif msg.DESCRIPTOR.fields_by_name.get("timestamp") is not None:
        msg.timestamp.CopyFrom(stamp(ns))


def _world_frames(msg) -> list[str]:
    """The frames a message places things in (a camera's own frame aside)."""
    if isinstance(msg, su_pb2.SceneUpdate):
        return [e.frame_id for e in msg.entities]
    if isinstance(msg, tf_pb2.FrameTransform):
        return [msg.parent_frame_id]
    if isinstance(msg, (pc_pb2.PointCloud, pif_pb2.PosesInFrame)):
        return [msg.frame_id]
    return []


def merge_viewers(path: str | os.PathLike, parts: Sequence[str | os.PathLike]) -> dict:
    """Write the viewer file `path` (atomically) holding every message of the viewer files `parts`; returns a
    summary: the parts, topics with their message counts, the world frames named (more than one: the parts do
    not share a frame and will not line up) and how many messages were re-stamped."""
    from mcap_protobuf.writer import Writer

    if not parts:
        raise ConfigError("nothing to combine: no viewer file given", parameter="viz")
    messages = [m for p in parts for m in _read(Path(p))]
    clocked = [ns for _, _, ns in messages if ns > 0]
    ref = min(clocked) if clocked else 0
    has_surface = any(t in _SURFACE for t, _, _ in messages)
    kept, restamped = [], 0
    for topic, msg, ns in messages:
        if topic == "/kinfu/occupied" and has_surface:
            continue
        if ns == 0 and ref:
            _restamp(msg, ref)
            ns, restamped = ref, restamped + 1
        kept.append((topic, msg, ns))
    kept.sort(key=lambda m: m[2])
    frames = sorted({f for _, m, _ in kept for f in _world_frames(m)} - {""})
    topics: dict[str, int] = {}
    with atomic_path(Path(path)) as tmp:
        with open(tmp, "wb") as fh, Writer(fh) as writer:
            for topic, msg, ns in kept:
                writer.write_message(topic, msg, log_time=ns, publish_time=ns)
                topics[topic] = topics.get(topic, 0) + 1
    return {"path": str(path), "parts": [str(p) for p in parts], "topics": topics, "frames": frames,
            "restamped": restamped, "dropped_occupied": has_surface and any(t == "/kinfu/occupied"
                                                                             for t, _, _ in messages)}
