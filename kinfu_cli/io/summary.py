"""What is in a recording: topics, time span, detected roles, TF tree and (optionally) usable RGB-D frames.

`recording_summary(path)` returns a JSON-able dict; `format_summary(summary)` the text `kinfu info` prints.
"""

from __future__ import annotations

import os
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from ruamel.yaml import YAML  # rosbags' own YAML library (PyYAML is not a dependency)

from kinfu_cli.core.errors import TransformError
from kinfu_cli.core.progress import progress
from kinfu_cli.io.frames import FrameStats, cloud_depth_source, iter_frames
from kinfu_cli.io.messages import POSE_TYPES
from kinfu_cli.io.realsense_bag import sdk_summary
from kinfu_cli.io.recording import Recording, open_recording
from kinfu_cli.io.roles import Roles, detect_roles
from kinfu_cli.io.tf_buffer import TfBuffer

FORMAT_NAMES = {"bag": "ROS 1 bag", "mcap": "MCAP", "ros2": "ROS 2 bag folder"}


def recording_summary(path: str | os.PathLike, check_frames: dict | None = None, quiet: bool = True,
                      **role_overrides: str | None) -> dict:
    """Summary of a recording as a JSON-able dict.

    check_frames: iter_frames keyword arguments; when given, every frame is assembled and the summary gets
    "frames": FrameStats (used, skipped, without colour, dropped by reason) and "warnings": what reading them
    found doubtful (FrameStats.warnings, as fuse and export say it). role_overrides: detect_roles arguments.
    """
    with open_recording(path) as rec:
        return summarize(rec, check_frames=check_frames, quiet=quiet, **role_overrides)


def summarize(rec: Recording, check_frames: dict | None = None, quiet: bool = True,
              **role_overrides: str | None) -> dict:
    """As recording_summary, on an open Recording."""
    tf = TfBuffer.from_recording(rec)
    problem = None
    try:
        roles = detect_roles(rec, tf=tf, **role_overrides)
    except TransformError as exc:  # the camera's TF chain loops or is broken: a summary shows why, frames fail
        if exc.parameter is not None or (check_frames is not None and check_frames.get("pose_source", "tf") == "tf"):
            raise  # a named frame that is not there, or frames that need the broken chain
        problem = str(exc)
        roles = detect_roles(rec, tf=tf, **{**role_overrides, "world_frame": ""})
        roles.world_frame = None
    frames, warnings = (None, []) if check_frames is None else _frame_stats(rec, roles, tf, check_frames, quiet)
    return {
        "path": str(rec.path),
        "format": rec.format,
        "storage": _ros2_storage(rec),
        "size_bytes": _size(rec.path),
        "start_ns": rec.start_ns,
        "end_ns": rec.end_ns,
        "duration_s": rec.duration_s,
        "message_count": rec.message_count,
        "topics": [t.as_dict() for t in rec.topics.values()],
        "roles": roles.as_dict(),
        **({"depth_cloud": cloud} if (cloud := cloud_depth_source(rec, roles)) is not None else {}),
        **({"realsense": rs} if (rs := sdk_summary(rec, roles.depth_topic, roles.color_topic)) is not None else {}),
        "tf": {"frames": tf.frames(), "tree": tf.tree(), "links": _tf_links(tf), "rejected": dict(tf.rejected),
               "rejected_links": [{"parent": p, "child": c, "rejected": dict(r)}
                                  for (p, c), r in tf.rejected_links.items()],
               "parent_changes": [list(c) for c in tf.parent_changes], "loops": tf.loops(), "problem": problem},
        "frames": frames,
        "problems": list(rec.problems),
        "warnings": warnings,
        "notes": (roles.notes if frames is None else []) + usage_notes(rec, roles, tf),  # frames say them too
    }


def usage_notes(rec: Recording, roles: Roles, tf: TfBuffer) -> list[str]:
    """What a recording without depth (poses or TF only) is still good for, naming its pose topics and moving
    TF frames; [] when it has a depth source."""
    if roles.depth_topic is not None:
        return []
    notes = ["no depth source (depth images or an organized point cloud): nothing to fuse, segment or export as "
             "frames"]
    poses = rec.topics_of_type(*POSE_TYPES)
    moving = [c for c in tf.tree() if not tf.is_static(c)]
    if poses:
        notes.append(f"pose topics: {', '.join(poses)}")
    if moving:
        shown = ", ".join(sorted(moving)[:8]) + (f" (+{len(moving) - 8} more)" if len(moving) > 8 else "")
        notes.append(f"moving TF frames: {shown}")
    if roles.hand_topic is None and roles.hand_frame is None and (poses or moving):
        notes.append("no hand detected by name: give one of these as the hand topic or hand frame for POIs, or as "
                     "the pose topic or camera frame of a TUM trajectory export")
    return notes


def _frame_stats(rec: Recording, roles: Roles, tf: TfBuffer, frame_kwargs: dict,
                 quiet: bool) -> tuple[dict, list[str]]:
    """Assemble every frame (decoding all images) and count the usable and the dropped ones; with the warnings of
    what was doubtful (colour cut short or missing, assumptions)."""
    stats = FrameStats()
    total = rec.topics[roles.depth_topic].count if roles.depth_topic in rec.topics else None
    for _ in progress(iter_frames(rec, roles, tf=tf, stats=stats, **frame_kwargs), total=total,
                      desc="frames", quiet=quiet, unit="frame"):
        pass
    return stats.as_dict(), stats.warnings(str(rec.path))


def _tf_links(tf: TfBuffer) -> list[dict]:
    """Each TF link with its parent, whether static, its number of samples and mean rate."""
    links = []
    for child, parent in tf.tree().items():
        stamps = tf.link_stamps(child)
        static = tf.is_static(child)
        rate = None
        if not static and stamps.size > 1 and stamps[-1] > stamps[0]:
            rate = (stamps.size - 1) / ((stamps[-1] - stamps[0]) * 1e-9)
        links.append({"parent": parent, "child": child, "static": static,
                      "samples": int(stamps.size), "rate_hz": rate})
    return links


def _ros2_storage(rec: Recording) -> str | None:
    """Storage plugin of a ROS 2 bag folder (sqlite3, mcap) from its metadata.yaml; None otherwise."""
    if rec.format != "ros2":
        return None
    try:
        meta = YAML(typ="safe").load((rec.path / "metadata.yaml").read_text())
        return meta["rosbag2_bagfile_information"]["storage_identifier"]
    except Exception:  # informative only
        return None


def _size(path: Path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _when(ns: int | None) -> str:
    if ns is None:
        return "-"
    return datetime.fromtimestamp(ns * 1e-9, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def format_summary(s: dict, roles_heading: str = "roles (detected):") -> str:
    """Human-readable text of a summary dict; roles_heading introduces the detected roles (a caller may say
    how to override them)."""
    fmt = FORMAT_NAMES[s["format"]] + (f" ({s['storage']} storage)" if s.get("storage") else "")
    lines = [f"recording: {s['path']}",
             f"format:    {fmt}, {s['size_bytes'] / 1e6:.2f} MB, {s['message_count']} messages",
             f"time span: {_when(s['start_ns'])} .. {_when(s['end_ns'])} ({s['duration_s']:.3f} s)",
             *(f"problem:   {p}" for p in s.get("problems", [])),
             ""]
    lines += _topic_lines(s["topics"])
    lines.append("")
    lines.append(roles_heading)
    for k, v in s["roles"].items():
        lines.append(f"  {k.replace('_', ' ') + ':':15s} {v if v is not None else '-'}")
    if s.get("depth_cloud"):
        lines += _cloud_lines(s["depth_cloud"])
    if s.get("realsense"):
        lines += _realsense_lines(s["realsense"])
    lines += [f"  note:           {n}" for n in s.get("notes", [])]
    lines.append("")
    lines += _tf_lines(s["tf"])
    if s.get("frames") is not None:
        lines.append("")
        lines += _frames_lines(s["frames"])
    return "\n".join(lines)


def _cloud_lines(c: dict) -> list[str]:
    """The organized point cloud read as depth: its size, colour and intrinsics (or why it cannot be read)."""
    if c.get("problem"):
        return [f"  depth cloud:    {c['topic']}: {c['problem']}"]
    k = c["intrinsics"]
    return [f"  depth cloud:    {c['width']}x{c['height']} organized point cloud, depth = z, colour: "
            f"{c['color'] or '-'}",
            f"  intrinsics ({c['intrinsics_source']}): fx={k['fx']:.2f} fy={k['fy']:.2f} cx={k['cx']:.2f} "
            f"cy={k['cy']:.2f}"]


def _realsense_lines(r: dict) -> list[str]:
    """A RealSense SDK recording: its layout, depth scale and where the colour goes (io.realsense_bag)."""
    lines = [f"  layout:         {r['layout']}"]
    if r.get("problem"):
        lines.append(f"  depth units:    problem: {r['problem']}")
    else:
        source = "assumed" if r["depth_units_source"] == "assumed" else f"from {r['depth_units_source']}"
        lines.append(f"  depth units:    {r['depth_units_m'] * 1000:g} mm per unit ({source})")
    reg = r.get("color_registration")
    if reg and reg["mode"] == "project":
        t = reg["T_color_depth"]
        offset = float(np.linalg.norm(np.asarray(t)[:3, 3])) * 1000
        lines.append(f"  colour:         projected from {reg['color_frame']} ({reg['color_info_topic']}) onto "
                     f"{reg['depth_frame']} through the recorded stream extrinsics ({offset:.1f} mm apart)")
    elif reg:
        lines.append(f"  colour:         left out: {reg['reason']}")
    lines += [f"  note:           {n}" for n in r.get("notes", [])]
    return lines


def _topic_lines(topics: list[dict]) -> list[str]:
    """The topic table: name, type(s), count, rate, in aligned columns."""
    heads = ("topic", "type", "count", "rate")
    rows = [(t["name"], ", ".join(t["msgtypes"]) or t["msgtype"], str(t["count"]),
             f"{t['rate_hz']:.2f} Hz" if t["rate_hz"] else "-") for t in topics]
    widths = [max([len(r[i]) for r in rows] + [len(h)]) for i, h in enumerate(heads)]

    def row(values) -> str:  # names and types left-aligned, numbers right-aligned
        return "  " + "  ".join(v.ljust(w) if i < 2 else v.rjust(w) for i, (v, w) in enumerate(zip(values, widths)))

    return ["topics:", row(heads)] + [row(r) for r in rows]


def _tf_lines(tf: dict) -> list[str]:
    """The TF frame tree, indented by depth, with each link's samples and rate; then rejected transforms and
    parent changes."""
    lines = []
    links = {link["child"]: link for link in tf["links"]}
    if not tf["frames"]:
        lines.append("TF tree: no /tf or /tf_static data")
    else:
        lines.append(f"TF tree ({len(tf['frames'])} frames):")
        children: dict[str, list[str]] = {}
        for child, parent in tf["tree"].items():
            children.setdefault(parent, []).append(child)

        def line(frame: str, depth: int) -> str:
            link = links.get(frame)
            if link is None:
                note = ""
            elif link["static"]:
                note = "  (static)"
            else:
                rate = f", {link['rate_hz']:.1f} Hz" if link["rate_hz"] else ""
                note = f"  ({link['samples']} samples{rate})"
            return "  " + "  " * depth + frame + note

        # depth first from each root, without recursion (a chain may be thousands of links long)
        stack = [(root, 0) for root in sorted((f for f in tf["frames"] if f not in tf["tree"]), reverse=True)]
        while stack:
            frame, depth = stack.pop()
            lines.append(line(frame, depth))
            stack.extend((c, depth + 1) for c in sorted(children.get(frame, []), reverse=True))
    for loop in tf.get("loops", []):
        lines.append(f"  loop (its frames are not in the tree above): {' -> '.join(loop)}")
    if tf.get("rejected_links"):
        for item in tf["rejected_links"]:
            for reason, n in item["rejected"].items():
                lines.append(f"  skipped {n} transforms {item['parent']!r} -> {item['child']!r}: {reason}")
    else:
        for reason, n in tf.get("rejected", {}).items():
            lines.append(f"  skipped {n} transforms: {reason}")
    for child, old, new in tf.get("parent_changes", []):
        lines.append(f"  note: {child} changed parent from {old} to {new} (lookups take the parent of their stamp)")
    if tf.get("problem"):
        lines.append(f"  problem: {tf['problem']}")
    return lines


def _frames_lines(fr: dict) -> list[str]:
    lines = [f"RGB-D frames: {fr['used']} usable of {fr['depth_messages']} depth messages "
             f"(skipped {fr['skipped']}, without colour {fr['without_color']})"]
    for reason, n in fr["dropped"].items():
        lines.append(f"  dropped {n}: {reason}")
    reg = fr.get("color_registration")  # its notes are warnings (stderr), as fuse and export say them
    if reg and reg["mode"] == "project":
        lines.append(f"  colour: projected from the colour camera ({reg['color_frame']}, {reg['color_info_topic']}) "
                     f"onto the depth camera ({reg['depth_frame']})")
    elif reg and reg["mode"] == "none":
        lines.append(f"  colour: left out: {reg['reason']}")
    return lines
