"""`kinfu info`: what is in a recording — topics, types, counts, rates, time span, roles, TF tree."""

from __future__ import annotations

import json
from datetime import datetime, timezone

import click

from kinfu_cli.io.frames import frame_kwargs, frame_options
from kinfu_cli.io.recording import Recording, open_recording
from kinfu_cli.io.roles import detect_roles, role_kwargs, role_options
from kinfu_cli.io.tf_buffer import TfBuffer

_FORMAT_NAMES = {"bag": "ROS 1 bag", "mcap": "MCAP", "ros2": "ROS 2 bag folder"}


def recording_summary(path, check_frames: dict | None = None, quiet: bool = True, **role_overrides) -> dict:
    """Summary of a recording as a JSON-able dict (what `kinfu info --json` prints).

    check_frames: iter_frames keyword arguments; when given, every frame is assembled and the summary gets
    "frames": FrameStats (used, skipped, without colour, dropped by reason).
    """
    with open_recording(path) as rec:
        return summarize(rec, check_frames=check_frames, quiet=quiet, **role_overrides)


def summarize(rec: Recording, check_frames: dict | None = None, quiet: bool = True, **role_overrides) -> dict:
    tf = TfBuffer.from_recording(rec)
    roles = detect_roles(rec, tf=tf, **role_overrides)
    frames = None
    if check_frames is not None:
        from kinfu_cli.io.frames import FrameStats, iter_frames
        from kinfu_cli.core.progress import progress

        stats = FrameStats()
        total = rec.topics[roles.depth_topic].count if roles.depth_topic in rec.topics else None
        for _ in progress(iter_frames(rec, roles, tf=tf, stats=stats, **check_frames), total=total,
                          desc="frames", quiet=quiet, unit="frame"):
            pass
        frames = stats.as_dict()
    links = []
    for child, parent in tf.tree().items():
        stamps = tf.link_stamps(child)
        static = tf.is_static(child)
        rate = None
        if not static and stamps.size > 1 and stamps[-1] > stamps[0]:
            rate = (stamps.size - 1) / ((stamps[-1] - stamps[0]) * 1e-9)
        links.append({"parent": parent, "child": child, "static": static,
                      "samples": int(stamps.size), "rate_hz": rate})
    storage = None
    if rec.format == "ros2":
        from ruamel.yaml import YAML  # rosbags' own YAML library (PyYAML is not a dependency)

        try:
            meta = YAML(typ="safe").load((rec.path / "metadata.yaml").read_text())
            storage = meta["rosbag2_bagfile_information"]["storage_identifier"]
        except Exception:  # informative only
            storage = None
    return {
        "path": str(rec.path),
        "format": rec.format,
        "storage": storage,
        "size_bytes": _size(rec.path),
        "start_ns": rec.start_ns,
        "end_ns": rec.end_ns,
        "duration_s": rec.duration_s,
        "message_count": rec.message_count,
        "topics": [t.as_dict() for t in rec.topics.values()],
        "roles": roles.as_dict(),
        "tf": {"frames": tf.frames(), "tree": tf.tree(), "links": links, "rejected": dict(tf.rejected),
               "parent_changes": [list(c) for c in tf.parent_changes]},
        "frames": frames,
    }


def _size(path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _when(ns: int | None) -> str:
    if ns is None:
        return "-"
    return datetime.fromtimestamp(ns * 1e-9, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def format_summary(s: dict) -> str:
    """Human-readable text of a summary dict."""
    lines = []
    fmt = _FORMAT_NAMES[s["format"]] + (f" ({s['storage']} storage)" if s.get("storage") else "")
    lines.append(f"recording: {s['path']}")
    lines.append(f"format:    {fmt}, {s['size_bytes'] / 1e6:.2f} MB, {s['message_count']} messages")
    lines.append(f"time span: {_when(s['start_ns'])} .. {_when(s['end_ns'])} ({s['duration_s']:.3f} s)")
    lines.append("")
    lines.append("topics:")
    rows = [(t["name"], ", ".join(t["msgtypes"]) or t["msgtype"], str(t["count"]),
             f"{t['rate_hz']:.2f} Hz" if t["rate_hz"] else "-") for t in s["topics"]]
    widths = [max([len(r[i]) for r in rows] + [len(h)]) for i, h in enumerate(("topic", "type", "count", "rate"))]
    lines.append("  " + "  ".join(h.ljust(w) if i < 2 else h.rjust(w)
                                  for i, (h, w) in enumerate(zip(("topic", "type", "count", "rate"), widths))))
    for r in rows:
        lines.append("  " + "  ".join(v.ljust(w) if i < 2 else v.rjust(w) for i, (v, w) in enumerate(zip(r, widths))))
    lines.append("")
    lines.append("roles (detected; override with --depth-topic, --world-frame, ...):")
    for k, v in s["roles"].items():
        lines.append(f"  {k.replace('_', ' ') + ':':15s} {v if v is not None else '-'}")
    lines.append("")
    links = {l["child"]: l for l in s["tf"]["links"]}
    if not s["tf"]["frames"]:
        lines.append("TF tree: no /tf or /tf_static data")
    else:
        lines.append(f"TF tree ({len(s['tf']['frames'])} frames):")
        children: dict[str, list[str]] = {}
        for child, parent in s["tf"]["tree"].items():
            children.setdefault(parent, []).append(child)
        roots = sorted(f for f in s["tf"]["frames"] if f not in s["tf"]["tree"])

        def walk(frame: str, depth: int) -> None:
            link = links.get(frame)
            if link is None:
                note = ""
            elif link["static"]:
                note = "  (static)"
            else:
                rate = f", {link['rate_hz']:.1f} Hz" if link["rate_hz"] else ""
                note = f"  ({link['samples']} samples{rate})"
            lines.append("  " + "  " * depth + frame + note)
            for c in sorted(children.get(frame, [])):
                walk(c, depth + 1)

        for root in roots:
            walk(root, 0)
    for reason, n in s["tf"].get("rejected", {}).items():
        lines.append(f"  skipped {n} transforms: {reason}")
    for child, old, new in s["tf"].get("parent_changes", []):
        lines.append(f"  note: {child} changed parent from {old} to {new} (the later link is kept)")
    fr = s.get("frames")
    if fr is not None:
        lines.append("")
        lines.append(f"RGB-D frames: {fr['used']} usable of {fr['depth_messages']} depth messages "
                     f"(skipped {fr['skipped']}, without colour {fr['without_color']})")
        for reason, n in fr["dropped"].items():
            lines.append(f"  dropped {n}: {reason}")
    return "\n".join(lines)


@click.command("info", short_help="Show topics, rates, time span, detected roles and TF tree of a recording.")
@click.argument("recording", type=click.Path(exists=False))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON on stdout.")
@click.option("--frames", "check", is_flag=True,
              help="Also assemble every RGB-D frame (decodes all images) and report how many are usable and why "
                   "the others are dropped; the frame options below apply.")
@frame_options
@click.option("-q", "--quiet", is_flag=True, help="No progress bar (with --frames).")
@role_options
def command(recording: str, as_json: bool, check: bool, quiet: bool, **kwargs) -> None:
    """Summarise RECORDING (MCAP file, ROS 1 .bag or ROS 2 bag folder): topics with message types, counts
    and rates, the time span, the topics and frames detected for each role (depth, colour, camera info,
    camera frame, world frame, hand) and the TF frame tree.

    \b
    Example:
      kinfu info sample_data/tabletop/recording.mcap
      kinfu info recording_ros2/ --json > summary.json
      kinfu info run.bag --frames --tolerance 0.02
    """
    fk = frame_kwargs(kwargs)
    summary = recording_summary(recording, check_frames=fk if check else None, quiet=quiet, **role_kwargs(kwargs))
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        click.echo(format_summary(summary))
