"""Which topic / frame plays which part: depth, colour, camera info, camera frame, world frame, hand.

Detected from message types and names; every role can be forced by the caller (`detect_roles` arguments,
which the command line exposes as options). A forced topic that is not in the recording is an error naming
it and listing the available topics.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field

from kinfu_cli.core.camera import parse_intrinsics
from kinfu_cli.core.errors import ConfigError, RecordingError, TransformError
from kinfu_cli.io.camera_info import image_camera
from kinfu_cli.io.messages import DEPTH_ENCODINGS, POSE_TYPES, header_frame
from kinfu_cli.io.pointcloud2 import POINTCLOUD2, has_color, is_cloud, organized_problem
from kinfu_cli.io.realsense_bag import is_sdk_recording, sdk_topic_roles
from kinfu_cli.io.tf_buffer import TfBuffer

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
_WORLD_NAMES = ("world", "map", "odom")
# message types a topic must carry to play a role (any one of them; a topic may mix types)
ROLE_TYPES = {"depth topic": (IMAGE, COMPRESSED, POINTCLOUD2), "colour topic": (IMAGE, COMPRESSED),
              "camera info topic": (CAMERA_INFO,), "hand topic": POSE_TYPES}
_ROLE_PARAMETERS = {"depth topic": "depth_topic", "colour topic": "color_topic", "camera info topic": "info_topic",
                    "hand topic": "hand_topic"}
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
    intrinsics: tuple[float, float, float, float] | None = None  # fx, fy, cx, cy given instead of a camera info
    # what detection chose among equals (several depth topics), a warning each for the commands that read frames
    notes: list[str] = field(default_factory=list, compare=False)

    def as_dict(self) -> dict:
        d = asdict(self)
        del d["notes"]
        d["intrinsics"] = None if self.intrinsics is None else list(self.intrinsics)
        return d


def require_role_topic(rec, topic: str, what: str):
    """TopicInfo of `topic`, which is to play the role `what` (a ROLE_TYPES key): RecordingError naming it when it
    is missing, or (naming the role's parameter) when it carries none of the role's message types."""
    info = rec.require_topic(topic, what)
    types = info.msgtypes or [info.msgtype]
    if not set(types) & set(ROLE_TYPES[what]):
        have = ", ".join(t or "messages without a type name" for t in types)
        raise RecordingError(f"{rec.path}: {what} {topic} carries {have}, expected "
                             f"{' or '.join(ROLE_TYPES[what])}", parameter=_ROLE_PARAMETERS[what])
    return info


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


def _cloud_candidates(rec) -> list[str]:
    """Organized PointCloud2 topics (a driver's /camera/depth/points): depth when no depth image topic exists;
    those carrying rgb first, then by name."""
    out: list[tuple[bool, str]] = []
    for name, info in rec.topics.items():
        if info.count and POINTCLOUD2 in info.msgtypes:
            msg = rec.first_message(name)
            if msg is not None and is_cloud(msg) and organized_problem(msg) is None:
                out.append((not has_color(msg), name))
    return [n for _, n in sorted(out)]


def unorganized_clouds(rec) -> list[tuple[str, str]]:
    """(topic, why it is no depth source) of each PointCloud2 topic that is not an organized x/y/z cloud."""
    out = []
    for name, info in rec.topics.items():
        if info.count and POINTCLOUD2 in info.msgtypes:
            msg = rec.first_message(name)
            why = organized_problem(msg) if msg is not None and is_cloud(msg) else None
            if why:
                out.append((name, why))
    return out


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
    # one in the depth image's optical frame wins (a colour camera's info holds another lens: fx 100 against the
    # depth camera's 58.5 was taken silently); then the same namespace (/camera/depth/camera_info for
    # /camera/depth/image_raw)
    depth_frame = _first_frame(rec, depth_topic)
    return sorted(infos, key=lambda n: (not depth_frame or _first_frame(rec, n) != depth_frame,
                                        -_common_prefix(n, depth_topic), "depth" not in n.lower(), n))[0]


def _first_frame(rec, topic: str) -> str:
    """The header frame of a topic's first message ("" when none)."""
    msg = rec.first_message(topic)
    return header_frame(msg).lstrip("/") if msg is not None else ""


def _pick_cloud_info(rec, cloud_topic: str) -> str | None:
    """The camera info of an organized cloud: one in the cloud's own optical frame whose size has the cloud's
    aspect ratio (depth_registered clouds are in the colour camera's frame), nearest in namespace; None (the
    intrinsics are then recovered from the cloud) when there is none."""
    first = rec.first_message(cloud_topic)
    frame = header_frame(first).lstrip("/") if first is not None else ""
    if not frame:
        return None
    h, w = int(first.height), int(first.width)
    found = []
    for name, info in rec.topics.items():
        if CAMERA_INFO not in info.msgtypes or not info.count:
            continue
        msg = rec.first_message(name)
        if msg is None or header_frame(msg).lstrip("/") != frame:
            continue
        try:
            _, iw, ih, *_ = image_camera(msg, name)
        except RecordingError:
            continue
        if iw and ih and abs(iw * h - ih * w) <= 0.01 * iw * h:
            found.append((-_common_prefix(name, cloud_topic), name))
    return min(found)[1] if found else None


def _pick_world(rec, tf: TfBuffer | None, camera_frame: str | None) -> str | None:
    """The world frame: the first of world, map, odom on the camera frame's TF chain, else the chain's root; with
    no camera frame in TF, the first of those names in the tree, else the first root. TransformError when the
    camera's chain loops, or stops short of a world/map/odom frame that the tree has (a missing or rejected link:
    picking the chain's root then would be a silent wrong answer), or when the camera's only links were rejected."""
    if tf is None or not tf.frames():
        return None
    frames = set(tf.frames())
    if camera_frame and camera_frame in frames:
        try:
            chain = tf.chain(camera_frame)
        except TransformError as exc:
            raise TransformError(f"{rec.path}: camera frame {camera_frame!r}: {exc}") from None
        for name in _WORLD_NAMES:
            if name in chain:
                return name
        world = next((name for name in _WORLD_NAMES if name in frames), None)
        if world is not None and tf.connected(world, camera_frame):  # re-parented: linked to it at other times
            return world
        if world is not None:
            raise TransformError(f"{rec.path}: {tf.broken_chain(camera_frame, world)}; name the world frame to "
                                 f"use {chain[-1]!r}")
        cut = next((p for (p, c) in tf.rejected_links if c == chain[-1]), None)  # the root's own parent, rejected
        if cut is not None:
            raise TransformError(f"{rec.path}: {tf.broken_chain(camera_frame, cut)}; name the world frame to use "
                                 f"{chain[-1]!r}")
        return chain[-1]
    if camera_frame and (bad := tf.rejected_link(camera_frame)) is not None:
        raise TransformError(f"{rec.path}: camera frame {camera_frame!r} has no TF link: every transform {bad[0]} "
                             f"was rejected ({bad[1]})")
    for name in _WORLD_NAMES:
        if name in frames:
            return name
    roots = sorted(f for f in frames if f not in tf.tree())
    return roots[0] if roots else None


def _require_frame(rec, tf: TfBuffer | None, frame: str, what: str, parameter: str,
                   header_frames: tuple[str, ...] = ()) -> None:
    """TransformError naming `parameter` unless the explicitly given `frame` is in the TF tree (or one of
    `header_frames`, the frame_id of the camera's own messages)."""
    if frame in header_frames or (tf is not None and frame in tf.frames()):
        return
    known = tf.frames() if tf is not None else []
    if tf is not None and (bad := tf.rejected_link(frame)) is not None:
        raise TransformError(f"{rec.path}: {what} {frame!r} has no TF link: every transform {bad[0]} was rejected "
                             f"({bad[1]})", parameter=parameter)
    avail = ", ".join(known[:30]) + (", ..." if len(known) > 30 else "") if known else "none: no TF data"
    raise TransformError(f"{rec.path}: {what} {frame!r} is not in the TF tree (frames: {avail})",
                         parameter=parameter)


def _first_cloud(rec, topic: str | None):
    """The first message of `topic` when it is a PointCloud2 topic, else None."""
    if topic is None or POINTCLOUD2 not in rec.topics[topic].msgtypes:
        return None
    msg = rec.first_message(topic)
    return msg if msg is not None and is_cloud(msg) else None


def detect_roles(rec, depth_topic: str | None = None, color_topic: str | None = None,
                 info_topic: str | None = None, camera_frame: str | None = None,
                 world_frame: str | None = None, hand_topic: str | None = None,
                 hand_frame: str | None = None, tf: TfBuffer | None = None,
                 intrinsics=None) -> Roles:
    """Roles of a Recording; arguments that are not None win over detection.

    `tf` may be passed to reuse an already-read TfBuffer (else the TF topics are read here when needed).
    intrinsics: the depth camera's fx, fy, cx, cy (pixels) for a recording without its camera info (or to
    override it); then no camera info topic is used.
    The depth topic may be an organized PointCloud2 (io.pointcloud2), detected only when no depth image topic
    exists. When that cloud has an rgb field, its colour is the frames' colour and no colour topic is detected
    (a colour topic given still wins); its camera info must be in the cloud's frame (else the intrinsics are
    recovered from the cloud when reading frames).
    A RealSense SDK recording (io.realsense_bag) has its first Depth and Color streams and the depth stream's
    camera info detected.
    """
    if intrinsics is not None:
        intrinsics = parse_intrinsics(intrinsics)
        if info_topic is not None:
            raise ConfigError("give either a camera info topic or intrinsics, not both", parameter="intrinsics")
    for topic, what in ((depth_topic, "depth topic"), (color_topic, "colour topic"),
                        (info_topic, "camera info topic"), (hand_topic, "hand topic")):
        if topic is not None:
            require_role_topic(rec, topic, what)

    sdk = depth_topic is None and is_sdk_recording(rec)
    if sdk:  # the RealSense SDK's layout: its Depth and Color streams (an Infrared stream is no colour)
        found = sdk_topic_roles(rec)
        depth_topic = found["depth_topic"]
        color_topic = color_topic if color_topic is not None else found["color_topic"]
        if info_topic is None and intrinsics is None:
            info_topic = found["info_topic"]
    notes = []
    if depth_topic is None:
        cands = _depth_candidates(rec) or _cloud_candidates(rec)  # a depth image wins over a cloud
        depth_topic = cands[0] if cands else None
        # two depth streams (a RealSense's depth and aligned_depth_to_color) are two cameras: say which was taken;
        # the same stream through image_transport (.../compressedDepth) is no other
        others = [c for c in cands[1:] if not c.startswith(f"{depth_topic}/")]
        if others:
            notes.append(f"{len(others) + 1} depth topics: {depth_topic} was taken (by name), not "
                         f"{', '.join(others)}; name the one to take as the depth topic")
    if color_topic is not None and color_topic == depth_topic:
        raise ConfigError(f"{color_topic} is the depth topic: expected a colour image topic", parameter="color_topic")
    cloud = _first_cloud(rec, depth_topic)
    if color_topic is None and not sdk and not (cloud is not None and has_color(cloud)):  # a cloud's rgb: registered
        cands = _color_candidates(rec, depth_topic)
        color_topic = cands[0] if cands else None
    # an SDK depth stream's camera info is its own or none: another stream's (the colour camera's) is no depth lens
    if info_topic is None and intrinsics is None and not sdk:
        info_topic = _pick_info(rec, depth_topic) if cloud is None else _pick_cloud_info(rec, depth_topic)

    given_camera = camera_frame
    header_frames: tuple[str, ...] = ()
    for topic in (depth_topic, info_topic):
        if topic is not None and (camera_frame is None or not header_frames):
            msg = rec.first_message(topic)
            frame = header_frame(msg).lstrip("/") if msg is not None else ""
            if frame:
                header_frames = (frame,)
                camera_frame = camera_frame or frame

    if hand_topic is None:
        poses = [n for n, i in rec.topics.items() if set(POSE_TYPES) & set(i.msgtypes) and i.count > 0]
        named = [n for n in poses if _HAND_WORDS.search(n)]
        hand_topic = named[0] if named else None

    need_tf = world_frame is None or (hand_topic is None and hand_frame is None) or bool(
        given_camera or world_frame or hand_frame)
    if need_tf and tf is None:
        tf = TfBuffer.from_recording(rec)
    if given_camera:
        _require_frame(rec, tf, camera_frame, "camera frame", "camera_frame", header_frames)
        own = [f for f in header_frames if f != given_camera and tf is not None and f in tf.frames()]
        if own:  # `--camera-frame link3` on an arm fused a 7.5 m grid of a scene displaced, with no word
            notes.append(f"camera frame {given_camera!r} was given, but the depth images are stamped in "
                         f"{own[0]!r}, a frame of the TF tree too: the images are placed by the poses of "
                         f"{given_camera!r}; right only when their own frame_id is wrong")
    if world_frame:
        _require_frame(rec, tf, world_frame, "world frame", "world_frame")
    if hand_frame:
        _require_frame(rec, tf, hand_frame, "hand frame", "hand_frame")
    if world_frame is None:
        world_frame = _pick_world(rec, tf, camera_frame)
    if hand_topic is None and hand_frame is None and tf is not None:
        hands = [f for f in tf.frames() if re.search(r"hand", f, re.I) and f != camera_frame]
        hand_frame = sorted(hands, key=len)[0] if hands else None

    return Roles(depth_topic=depth_topic, color_topic=color_topic, info_topic=info_topic,
                 camera_frame=camera_frame, world_frame=world_frame, hand_topic=hand_topic,
                 hand_frame=hand_frame, intrinsics=intrinsics, notes=notes)

