"""The measurements of `kinfu localize`: a PLY point cloud, a text file of contact points in measurement
order (x y z per line, spaces or commas, '#' comments), or one segment of a `kinfu segment` output
(segments.json + the segments.ply beside it, where each segment is one colour)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.labelled_cloud import LabelsFileError, ply_points, read_ply_vertices
from kinfu_cli.localization.mesh_model import LocalizationError
from kinfu_cli.localization.mupf import check_points
from kinfu_cli.segmentation.outputs import segment_colors


def read_points(path: str | os.PathLike) -> np.ndarray:
    """(L, 3) points from a PLY or a text file, in file order."""
    path = Path(path)
    if not path.is_file():
        raise LocalizationError(f"{path}: no such points file")
    if path.suffix.lower() == ".ply":
        try:
            return _checked(ply_points(read_ply_vertices(path), path), path)
        except LabelsFileError as e:
            raise LocalizationError(str(e)) from None
    try:
        text = path.read_text()
        rows = [ln.split("#")[0].replace(",", " ").split() for ln in text.splitlines()]
        rows = [r for r in rows if r]
        pts = np.array([[float(v) for v in r] for r in rows], dtype=float).reshape(len(rows), -1)
    except (ValueError, UnicodeDecodeError):
        raise LocalizationError(f"{path}: expected lines of three numbers 'x y z' (a text points file)") from None
    if pts.size and pts.shape[1] != 3:
        raise LocalizationError(f"{path}: expected three numbers per line, found {pts.shape[1]}")
    return _checked(pts.reshape(-1, 3), path)


def _checked(pts: np.ndarray, path: Path) -> np.ndarray:
    """pts when `mupf.check_points` takes them (finite, within MAX_COORDINATE_M, enough); else its complaint
    naming the file."""
    try:
        check_points(pts, str(path))
    except ConfigError as e:
        raise LocalizationError(str(e)) from None
    return pts


def read_segment_points(segments_json: str | os.PathLike, segment: int) -> np.ndarray:
    """The points of segment `segment` from a kinfu segment output (its colour in segments.ply; the count is
    checked against segments.json so two segments sharing a colour are an error, not a merged cloud)."""
    meta = Path(segments_json)
    try:
        doc = json.loads(meta.read_text())
        # a background segment (segmentation/background.py) has its colour in segments.ply too: named, it is read
        segs = {int(s["id"]): s for s in doc["segments"] if s.get("kind") in ("object", "background")}
    except FileNotFoundError:
        raise LocalizationError(f"{meta}: no such segments file") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError,  # a segment not an object,
            OverflowError):  # an id of Infinity
        raise LocalizationError(f"{meta}: not a kinfu segment segments.json") from None  # JSON nested too deep
    if segment not in segs:
        raise LocalizationError(f"{meta}: no object segment with id {segment} (ids: "
                                f"{', '.join(map(str, sorted(segs))) or 'none'})", parameter="segment")
    count = segs[segment].get("point_count")
    if isinstance(count, bool) or not isinstance(count, (int, float)) or not math.isfinite(count) or count < 0 \
            or count != int(count):
        raise LocalizationError(f"{meta}: segment {segment}'s point_count is {count!r}, expected a number of points")
    count = int(count)
    ply = meta.parent / "segments.ply"
    try:
        vertex = read_ply_vertices(ply)
        pts = ply_points(vertex, ply)
    except LabelsFileError as e:  # it names the file: a wrong row count, a damaged file
        raise LocalizationError(str(e)) from None
    try:
        rgb = np.stack([vertex["red"], vertex["green"], vertex["blue"]], axis=1).astype(np.int64)
    except ValueError as e:
        raise LocalizationError(f"{ply}: segment colours unreadable ({e})") from None
    want = np.round(segment_colors(np.array([segment]))[0] * 255).astype(np.int64)
    mask = np.all(np.abs(rgb - want) <= 1, axis=1)
    if int(mask.sum()) != count:
        raise LocalizationError(f"{ply}: {int(mask.sum())} points carry segment {segment}'s colour, segments.json "
                                f"says {count} (another segment may share it)")
    return _checked(pts[mask], ply)
