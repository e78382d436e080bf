"""Labelled point clouds: the segmentation ground-truth format, which a person can also make.

A labels file is a PLY point cloud whose vertices carry x, y, z and an integer scalar `label` (0 = background:
table, floor, walls; 1.. = one number per object; -1 = not labelled). CloudCompare exports a scalar field named
`label` as the float property `scalar_label`; both names are read, float values must be whole numbers. Colours
and normals may be present and are ignored. A `.npz` with `points` (N, 3) and `labels` (N,) is read too.
`kinfu synth` writes ground_truth/labels.ply in this format; open3d writes it with
`o3d.t.io.write_point_cloud` after `pcd.point["label"] = labels[:, None].astype(np.int32)`.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.errors import KinfuError

LABEL_FIELDS = ("label", "scalar_label")


class LabelsFileError(KinfuError):
    """A labels file that cannot be read as one (one line, naming the file)."""


@dataclass
class LabelledCloud:
    """points (N, 3) float64 and labels (N,) int64."""

    points: np.ndarray
    labels: np.ndarray
    path: Path | None = None


NPZ_EXPECTED = "expected a .npz archive of arrays 'points' (N, 3) and 'labels' (N,)"


def _read_npz(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The points and labels arrays of a .npz; a truncated or foreign file is a LabelsFileError naming it."""
    try:
        archive = np.load(path, allow_pickle=False)
    except MemoryError:
        raise LabelsFileError(f"{path}: {NPZ_EXPECTED}; it declares arrays too large to read") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise LabelsFileError(f"{path}: {NPZ_EXPECTED}; it is truncated or not a .npz ({_first_line(e)})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise LabelsFileError(f"{path}: {NPZ_EXPECTED}, found a single .npy array")
    with archive:
        if "points" not in archive or "labels" not in archive:
            raise LabelsFileError(f"{path}: {NPZ_EXPECTED}, found {', '.join(archive.files) or 'none'}")
        try:  # members are read (and checked) only here: a damaged one fails now
            points, labels = archive["points"], archive["labels"]
        except MemoryError:
            raise LabelsFileError(f"{path}: {NPZ_EXPECTED}; it declares arrays too large to read") from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
            raise LabelsFileError(f"{path}: {NPZ_EXPECTED}; an array is truncated or damaged ({_first_line(e)})") \
                from None
    for name, arr in (("points", points), ("labels", labels)):
        if not isinstance(arr, np.ndarray):  # a zip member that is no .npy array comes back as bytes
            raise LabelsFileError(f"{path}: {NPZ_EXPECTED}; '{name}' is not a numpy array")
    return points, labels


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _checked(points: np.ndarray, labels: np.ndarray, path: Path) -> LabelledCloud:
    points, lab = np.asarray(points), np.asarray(labels)
    if points.dtype.kind not in "iuf":  # complex, strings, records: no coordinates (and no silent casts)
        raise LabelsFileError(f"{path}: expected points of real numbers, got dtype {points.dtype}")
    if lab.ndim not in (1, 2) or (lab.ndim == 2 and lab.shape[1] != 1):
        raise LabelsFileError(f"{path}: expected labels of shape (N,) or (N, 1), got {lab.shape}")
    pts = points.astype(np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise LabelsFileError(f"{path}: expected points of shape (N, 3), got {pts.shape}")
    lab = lab.reshape(-1)
    if len(lab) != len(pts):
        raise LabelsFileError(f"{path}: {len(pts)} points but {len(lab)} labels")
    if len(pts) == 0:
        raise LabelsFileError(f"{path}: no points")
    if not np.all(np.isfinite(pts)):
        raise LabelsFileError(f"{path}: {int(np.sum(~np.isfinite(pts).all(axis=1)))} points are not finite")
    if lab.dtype.kind == "f":
        if not np.all(np.isfinite(lab)) or np.any(lab != np.round(lab)):
            raise LabelsFileError(f"{path}: labels must be whole numbers (got fractional or NaN values)")
    elif lab.dtype.kind not in "iu":
        raise LabelsFileError(f"{path}: labels must be integers, got {lab.dtype}")
    big = np.abs(lab.astype(np.float64)) >= 2.0 ** 62  # uint64 2**64-1 would wrap to -1 (not labelled)
    if np.any(big):
        raise LabelsFileError(f"{path}: labels must be object numbers below 2**62, got {lab[big][0]}")
    lab = lab.astype(np.int64)
    if lab.min() < -1:
        raise LabelsFileError(f"{path}: labels must be >= -1 (-1 = not labelled), got {int(lab.min())}")
    return LabelledCloud(pts, lab, path)


def read_labelled_cloud(path: str | os.PathLike) -> LabelledCloud:
    """A labels file (.ply with a `label` / `scalar_label` vertex property, or .npz with points + labels)."""
    path = Path(path)
    if not path.is_file():
        raise LabelsFileError(f"{path}: no such labels file")
    if path.suffix.lower() == ".npz":
        return _checked(*_read_npz(path), path)
    if path.suffix.lower() != ".ply":
        raise LabelsFileError(f"{path}: expected a .ply point cloud with a per-point 'label' or a .npz")
    vertex = read_ply_vertices(path)
    names = vertex.dtype.names or ()
    field = next((f for f in LABEL_FIELDS if f in names), None)
    if field is None:
        raise LabelsFileError(f"{path}: no per-point 'label' property (found {', '.join(names)})")
    return _checked(ply_points(vertex, path), vertex[field], path)


# whitespace after a binary PLY's last row that is taken as a trailing line end, not as bytes of rows the header
# does not count
MAX_TRAILING_WHITESPACE = 64
# what bytes.strip() takes as blank: a line of only these after an ascii PLY's rows is no row
BLANK = " \t\n\r\x0b\x0c"


def read_ply_vertices(path: Path) -> np.ndarray:
    """The vertex element of a PLY file as a numpy structured array (LabelsFileError when unreadable)."""
    from plyfile import PlyData, PlyElementParseError, PlyParseError  # only labels files need it

    try:
        ply, rows_after = _read_ascii_ply(path, PlyData)
        bytes_after = None
        if ply is None:  # binary: plyfile stops right after the declared rows (and memory-maps them)
            with open(path, "rb") as fh:
                ply = PlyData.read(fh)
                bytes_after = os.fstat(fh.fileno()).st_size - fh.tell()
                if bytes_after and bytes_after <= MAX_TRAILING_WHITESPACE and not fh.read().strip(b" \t\r\n"):
                    bytes_after = 0  # a line end written after the data (by hand or a text tool): no row
        vertex = ply["vertex"].data
    except LabelsFileError:
        raise
    except KeyError:
        raise LabelsFileError(f"{path}: PLY file without a vertex element") from None
    except PlyElementParseError as e:
        if e.message == "early end-of-file" and e.element is not None and e.row is not None:
            raise LabelsFileError(f"{path}: the header declares {e.element.count} {e.element.name} rows "
                                  f"(element {e.element.name} {e.element.count}) but the file holds {e.row}: "
                                  f"truncated, or a wrong count in the header") from None
        raise LabelsFileError(f"{path}: unreadable PLY (truncated or malformed: {_first_line(e)})") from None
    except MemoryError:
        raise LabelsFileError(f"{path}: the PLY header declares more rows than can be read (a wrong element "
                              f"count?)") from None
    except (PlyParseError, ValueError, EOFError, OSError, IndexError, TypeError) as e:
        raise LabelsFileError(f"{path}: unreadable PLY (truncated or malformed: {_first_line(e)})") from None
    _check_no_extra_rows(path, ply, bytes_after, rows_after)
    return vertex


def _read_ascii_ply(path: Path, PlyData) -> tuple:
    """An ascii PLY and the non-blank lines after its declared rows, from one read: plyfile reads the rows of a
    text stream line by line and leaves it right after them (from a binary stream it reads ahead in a text
    wrapper of its own and closes the file). (None, 0) for a binary PLY, which plyfile refuses from text."""
    with open(path, encoding="ascii", errors="surrogateescape", newline="") as text:
        if text.read(3) != "ply":
            raise LabelsFileError(f"{path}: not a PLY file")
        text.seek(0)
        try:
            ply = PlyData.read(text)
        except ValueError:  # a binary format (or header text beyond ASCII: the binary read refuses that as before)
            return None, 0
        return ply, sum(1 for line in text if line.strip(BLANK))


def _check_no_extra_rows(path: Path, ply, bytes_after: int | None, rows_after: int) -> None:
    """Rows past the header's counts mean the counts are wrong: plyfile stops at them and would hand back a
    partial cloud (a truncated file fails in plyfile already). bytes_after: what follows a binary PLY's rows;
    rows_after: the non-blank lines after an ascii PLY's."""
    declared = ", ".join(f"element {el.name} {el.count}" for el in ply.elements)
    last = ply.elements[-1] if ply.elements else None
    if bytes_after:
        row_size = last.data.dtype.itemsize if last is not None and last.data.dtype.fields else 0
        if row_size and not any(t.kind == "O" for t, *_ in last.data.dtype.fields.values()) \
                and bytes_after % row_size == 0:
            rows = bytes_after // row_size
            extra = f"{rows} more {last.name} row{'s' * (rows != 1)}"
        else:
            extra = f"{bytes_after} more bytes"
        raise LabelsFileError(f"{path}: the header declares {declared} but the file holds {extra}: a wrong count "
                              f"in the header (or a damaged file)")
    if rows_after:
        raise LabelsFileError(f"{path}: the header declares {declared} but the file holds {rows_after} more "
                              f"row{'s' * (rows_after != 1)}: a wrong count in the header")


def ply_points(vertex: np.ndarray, path: Path) -> np.ndarray:
    """(N, 3) float64 x, y, z of a PLY vertex array."""
    names = vertex.dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise LabelsFileError(f"{path}: vertices lack x, y, z (found {', '.join(names)})")
    if any(vertex.dtype[k].kind not in "fiu" or vertex.dtype[k].shape for k in "xyz"):
        raise LabelsFileError(f"{path}: vertex x, y, z are not numbers (a list property?)")
    return np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1).astype(np.float64)


def write_labelled_cloud(path: str | os.PathLike, points: np.ndarray, labels: np.ndarray,
                         colors: np.ndarray | None = None) -> Path:
    """Write a labels file (binary PLY: x, y, z float32, label int32, optional uint8 colours) atomically."""
    import open3d as o3d  # heavy; only the PLY writer is needed

    path = Path(path)
    pc = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.asarray(points, dtype=np.float32)))
    pc.point["label"] = o3d.core.Tensor(np.asarray(labels, dtype=np.int32).reshape(-1, 1))
    if colors is not None:
        pc.point["colors"] = o3d.core.Tensor(np.asarray(colors, dtype=np.float32))
    with atomic_path(path) as tmp:
        if not o3d.t.io.write_point_cloud(str(tmp), pc, write_ascii=False):
            raise LabelsFileError(f"{path}: open3d could not write the labelled cloud")
    return path
