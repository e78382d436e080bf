"""Which topic / frame plays which part: depth, colour, camera info, camera frame, world frame, hand.

Detected from message types and names; every role can be forced by the caller (`detect_roles` arguments,
which the command line exposes as options). A forced topic that is not in the recording is an error naming
it and listing the available topics.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass

from kinfu_cli.io.messages import DEPTH_ENCODINGS, POSE_TYPES, header_frame
from kinfu_cli.io.tf_buffer import TfBuffer

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
_WORLD_NAMES = ("world", "map", "odom")
_HAND_WORDS = re.compile(r"hand|wrist|tracker|polhemus|glove", re.I)


@dataclass
class Roles:
    """Topics and frames of a recording; None where there is none."""

    depth_topic: str | None = None
    color_topic: str | None = None
    info_topic: str | None = None
    camera_frame: str | None = None
    world_frame: str | None = None
    hand_topic: str | None = None
    hand_frame: str | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def _common_prefix(a: str, b: str) -> int:
    pa, pb = a.strip("/").split("/"), b.strip("/").split("/")
    n = 0
    for x, y in zip(pa, pb):
        if x != y:
            break
        n += 1
    return n


def _depth_candidates(rec) -> list[str]:
    """Image topics holding depth (by encoding of the first message, or by name), CompressedImage compressedDepth."""
    out: list[tuple[int, str]] = []
    for name, info in rec.topics.items():
        if info.count == 0:
            continue
        low = name.lower()
        if IMAGE in info.msgtypes:
            if "depth" in low:
                out.append((0 if "raw" in low or "rect" in low else 1, name))
            elif not re.search(r"colou?r|rgb|mono|ir\b|infra", low):
                msg = rec.first_message(name)
                if msg is not None and str(getattr(msg, "encoding", "")) in DEPTH_ENCODINGS:
                    out.append((2, name))
        elif COMPRESSED in info.msgtypes and "compresseddepth" in low:
            out.append((3, name))
    return [n for _, n in sorted(out)]


def _color_candidates(rec, depth_topic: str | None) -> list[str]:
    out: list[tuple[int, int, str]] = []
    for name, info in rec.topics.items():
        if info.count == 0 or name == depth_topic:
            continue
        low = name.lower()
        if "depth" in low:
            continue
        if IMAGE in info.msgtypes or (COMPRESSED in info.msgtypes and "compresseddepth" not in low):
            score = 0 if re.search(r"colou?r|rgb", low) else 1
            if COMPRESSED in info.msgtypes:
                score += 2  # prefer raw images when both exist
            if IMAGE in info.msgtypes and score % 2 == 1:
                msg = rec.first_message(name)
                if msg is not None and str(getattr(msg, "encoding", "")) in DEPTH_ENCODINGS:
                    continue
            out.append((score, -_common_prefix(name, depth_topic or ""), name))
    return [n for *_, n in sorted(out)]


def _pick_info(rec, depth_topic: str | None) -> str | None:
    infos = [n for n, i in rec.topics.items() if CAMERA_INFO in i.msgtypes and i.count > 0]
    if not infos:
        return None
    if depth_topic is None:
        return infos[0]
    # same namespace as the depth image wins (/camera/depth/camera_info for /camera/depth/image_raw)
    return sorted(infos, key=lambda n: (-_common_prefix(n, depth_topic), "depth" not in n.lower(), n))[0]


def _pick_world(tf: TfBuffer | None, camera_frame: str | None) -> str | None:
    if tf is None or not tf.frames():
        return None
    tree = tf.tree()
    if camera_frame and camera_frame in tf.frames():
        chain = [camera_frame]
        while chain[-1] in tree:
            chain.append(tree[chain[-1]])
        for name in _WORLD_NAMES:
            if name in chain:
                return name
        return chain[-1]
    for name in _WORLD_NAMES:
        if name in tf.frames():
            return name
    roots = sorted({f for f in tf.frames() if f not in tree})
    return roots[0] if roots else None


def detect_roles(rec, depth_topic: str | None = None, color_topic: str | None = None,
                 info_topic: str | None = None, camera_frame: str | None = None,
                 world_frame: str | None = None, hand_topic: str | None = None,
                 hand_frame: str | None = None, tf: TfBuffer | None = None) -> Roles:
    """Roles of a Recording; arguments that are not None win over detection.

    `tf` may be passed to reuse an already-read TfBuffer (else the TF topics are read here when needed).
    """
    for topic, what in ((depth_topic, "depth topic"), (color_topic, "colour topic"),
                        (info_topic, "camera info topic"), (hand_topic, "hand topic")):
        if topic is not None:
            rec.require_topic(topic, what)

    if depth_topic is None:
        cands = _depth_candidates(rec)
        depth_topic = cands[0] if cands else None
    if color_topic is None:
        cands = _color_candidates(rec, depth_topic)
        color_topic = cands[0] if cands else None
    if info_topic is None:
        info_topic = _pick_info(rec, depth_topic)

    if camera_frame is None:
        for topic in (depth_topic, info_topic):
            if topic is not None:
                msg = rec.first_message(topic)
                frame = header_frame(msg).lstrip("/") if msg is not None else ""
                if frame:
                    camera_frame = frame
                    break

    if hand_topic is None:
        poses = [n for n, i in rec.topics.items() if set(POSE_TYPES) & set(i.msgtypes) and i.count > 0]
        named = [n for n in poses if _HAND_WORDS.search(n)]
        hand_topic = named[0] if named else None

    need_tf = world_frame is None or (hand_topic is None and hand_frame is None)
    if need_tf and tf is None:
        tf = TfBuffer.from_recording(rec)
    if world_frame is None:
        world_frame = _pick_world(tf, camera_frame)
    if hand_topic is None and hand_frame is None and tf is not None:
        hands = [f for f in tf.frames() if re.search(r"hand", f, re.I) and f != camera_frame]
        hand_frame = sorted(hands, key=len)[0] if hands else None

    return Roles(depth_topic=depth_topic, color_topic=color_topic, info_topic=info_topic,
                 camera_frame=camera_frame, world_frame=world_frame, hand_topic=hand_topic,
                 hand_frame=hand_frame)

