"""The fusion volume file (`volume.npz`): format name and version, writer and validating reader.

One .npz holding `meta` (a JSON string: format, format_version, shape, voxel_size, origin, truncation,
max_weight, min_depth, max_depth, color, block, frames_integrated, frame, and since the up direction and
intrinsics are recorded: up (unit [x, y, z] against gravity or null), up_source, intrinsics ({fx, fy, cx, cy,
width, height} of the depth camera fused, or null); readers treat missing ones as null) and the block-sparse arrays
`block_idx`, `block_w`, `pool_v`, `pool_w`, `pool_c` (see fusion/kernels.py for their meaning). Volumes fused
with the colour mode filter (meta `color_mode` "mode"; absent means "mean") carry the winning colour in `pool_c`
and also `pool_hc` (n, 512, M, 3) and `pool_hn` (n, 512, M), the hypotheses (fusion/color_mode.py). The
reader checks format and version here so every stage reports a foreign file the same way; turning the
arrays back into a TernaryVolume is fusion's job (`fusion.volume.load_volume`).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import write_npz
from kinfu_cli.core.errors import VolumeError

INTRINSICS_KEYS = ("fx", "fy", "cx", "cy", "width", "height")

FORMAT = "kinfu-volume"
FORMAT_VERSION = 1
ARRAYS = ("block_idx", "block_w", "pool_v", "pool_w", "pool_c")
OPTIONAL_ARRAYS = ("pool_hc", "pool_hn")  # colour mode filter hypotheses, only with color_mode "mode"
COLOR_MODES = ("mean", "mode")
VOXELS_PER_BLOCK = 512  # a pool row: one 8x8x8 block
MAX_COORDINATE_M = 1e6  # farther than this from the world origin is corrupt data, not a scene
# the bounds of a grid, for TernaryVolume (fusion/volume.py) and its files: a file beyond them is refused here,
# naming the file, rather than by the volume without it
MIN_VOXEL_M = 1e-4  # a tenth of a millimetre: finer is no depth sensor's scale
MAX_RANGE_M = 100.0  # voxel edge, truncation and depth range: farther is no depth sensor (and overflows float32 casts)
MAX_VOXELS_PER_AXIS = 1 << 16

# what a damaged or foreign .npz raises inside np.load / zipfile / zlib: the file is unreadable, not kinfu broken
READ_ERRORS = (OSError, ValueError, EOFError, KeyError, TypeError, IndexError, zipfile.BadZipFile, zlib.error,
               struct.error, NotImplementedError, RuntimeError, OverflowError, MemoryError, RecursionError)


def write_volume_file(path: str | os.PathLike, meta: dict, arrays: dict[str, np.ndarray]) -> Path:
    """Write `meta` (JSON-able, with format and format_version) and the block arrays atomically."""
    extra = {k: arrays[k] for k in OPTIONAL_ARRAYS if k in arrays}
    return write_npz(path, {"meta": np.array(json.dumps(meta)), **{k: arrays[k] for k in ARRAYS}, **extra})


def read_volume_file(path: str | os.PathLike, optional: bool = True) -> tuple[dict, dict[str, np.ndarray]]:
    """(meta, arrays) of a volume.npz; VolumeError for a missing, unreadable, foreign or other-version file.
    optional=False leaves OPTIONAL_ARRAYS (the mode filter's hypotheses, 5x the rest) compressed on disk."""
    path = Path(path)
    if not path.exists():
        raise VolumeError(f"{path}: no such volume file")
    check_npz(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            if "meta" not in data.files:
                raise VolumeError(f"{path}: not a kinfu volume.npz (no 'meta' array; a ternary.npz cannot be "
                                  f"fused into)")
            meta = json.loads(str(data["meta"]))
            if not isinstance(meta, dict):
                raise VolumeError(f"{path}: volume metadata is not a JSON object")
            if meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
                raise VolumeError(f"{path}: volume format {meta.get('format')!r} version "
                                  f"{meta.get('format_version')!r}, expected {FORMAT!r} version {FORMAT_VERSION}")
            missing = [k for k in ARRAYS if k not in data.files]
            if missing:
                raise VolumeError(f"{path}: volume file lacks the arrays {', '.join(missing)}")
            arrays = {k: data[k] for k in ARRAYS + (OPTIONAL_ARRAYS if optional else ()) if k in data.files}
    except VolumeError:
        raise
    except READ_ERRORS as exc:
        raise VolumeError(f"{path}: not a readable volume file ({_short(exc)}); it may be truncated or "
                          f"corrupt") from None
    _check(path, meta, arrays)
    return meta, arrays


def read_volume_meta(path: str | os.PathLike) -> dict | None:
    """The meta dict of a volume.npz without reading its arrays; None for an .npz without 'meta' (a
    ternary.npz); VolumeError for a missing or unreadable file."""
    path = Path(path)
    if not path.exists():
        raise VolumeError(f"{path}: no such volume file")
    check_npz(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"])) if "meta" in data.files else None
    except READ_ERRORS as exc:
        raise VolumeError(f"{path}: not a readable volume file ({_short(exc)}); it may be truncated or "
                          f"corrupt") from None
    if meta is not None and not isinstance(meta, dict):
        raise VolumeError(f"{path}: volume metadata is not a JSON object")
    return meta


def npz_member_header(data: np.lib.npyio.NpzFile, key: str) -> tuple[tuple[int, ...], np.dtype]:
    """Shape and dtype of array `key` of an open .npz, from its .npy header alone: what reading the array would
    allocate, known before it is decompressed. The errors of a damaged member are READ_ERRORS."""
    name = f"{key}.npy" if f"{key}.npy" in data.zip.namelist() else key
    with data.zip.open(name) as fh:
        version = np.lib.format.read_magic(fh)
        # 3.0 differs from 2.0 only in allowing a UTF-8 header, which a plain integer array does not use
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, _, dtype = read(fh)
    return tuple(int(n) for n in shape), dtype


def check_npz(path: Path) -> None:
    """An .npz is a zip archive: anything else (a JSON, a PLY) is named as such, before numpy's loader falls back
    to pickles and reports that instead."""
    with contextlib.suppress(OSError), open(path, "rb") as f:
        head = f.read(4)
        if head and head not in (b"PK\x03\x04", b"PK\x05\x06"):  # an empty file: numpy's "truncated" below
            raise VolumeError(f"{path}: not an .npz file (expected a volume.npz or ternary.npz that kinfu wrote)")


def _short(exc: BaseException) -> str:
    text = str(exc).replace("\n", " ").strip() or type(exc).__name__
    return text if len(text) <= 160 else text[:160] + "..."


def _number(meta: dict, key: str, path: Path, low: float, high: float, integer: bool = False,
            low_open: bool = False) -> float:
    v = meta.get(key)
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and low <= v <= high
    ok = ok and (not integer or float(v).is_integer()) and (not low_open or v > low)
    if not ok:
        what = "an integer" if integer else "a number"
        raise VolumeError(f"{path}: volume metadata {key!r} is {v!r}, expected {what} in "
                          f"{'(' if low_open else '['}{low:g}, {high:g}]")
    return v


def _check(path: Path, meta: object, arrays: dict[str, np.ndarray]) -> None:
    """VolumeError naming the file unless the metadata and arrays describe one consistent volume (so that no
    kernel indexes outside its arrays)."""
    if not isinstance(meta, dict):
        raise VolumeError(f"{path}: volume metadata is not a JSON object")
    shape = meta.get("shape")
    if not (isinstance(shape, list) and len(shape) == 3 and all(
            isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_VOXELS_PER_AXIS for n in shape)):
        raise VolumeError(f"{path}: volume metadata 'shape' is {shape!r}, expected three voxel counts in "
                          f"[1, {MAX_VOXELS_PER_AXIS}]")
    _number(meta, "voxel_size", path, MIN_VOXEL_M, MAX_RANGE_M)
    origin = meta.get("origin")
    if not (isinstance(origin, list) and len(origin) == 3 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            and abs(v) <= MAX_COORDINATE_M for v in origin)):
        raise VolumeError(f"{path}: volume metadata 'origin' is {origin!r}, expected three finite coordinates "
                          f"within {MAX_COORDINATE_M:g} m")
    _number(meta, "truncation", path, 0.0, MAX_RANGE_M, low_open=True)
    _number(meta, "max_weight", path, 1, 255, integer=True)
    lo = _number(meta, "min_depth", path, 0.0, MAX_RANGE_M)
    hi = _number(meta, "max_depth", path, 0.0, MAX_RANGE_M)
    if not lo < hi:
        raise VolumeError(f"{path}: volume metadata min_depth {lo} is not below max_depth {hi}")
    if not isinstance(meta.get("color"), bool):
        raise VolumeError(f"{path}: volume metadata 'color' is {meta.get('color')!r}, expected true or false")
    if meta.get("color_mode", "mean") not in COLOR_MODES:
        raise VolumeError(f"{path}: volume metadata 'color_mode' is {meta.get('color_mode')!r}, expected one of "
                          f"{', '.join(COLOR_MODES)}")
    if meta.get("color_mode") == "mode":
        _number(meta, "color_hypotheses", path, 1, 16, integer=True)
        _number(meta, "color_threshold", path, 0.0, 442.0, low_open=True)
    if "frames_integrated" in meta:
        _number(meta, "frames_integrated", path, 0, 2 ** 62, integer=True)
    if not isinstance(meta.get("frame", ""), (str, type(None))):
        raise VolumeError(f"{path}: volume metadata 'frame' is {meta.get('frame')!r}, expected a frame name")
    idx, bw, pv, pw, pc = (arrays[k] for k in ARRAYS)
    if idx.ndim != 3 or idx.dtype.kind not in "iu" or bw.shape != idx.shape or bw.dtype.kind not in "iu":
        raise VolumeError(f"{path}: block tables are {idx.dtype} {idx.shape} and {bw.dtype} {bw.shape}, expected "
                          f"two integer arrays of one 3-D shape")
    n = pv.shape[0] if pv.ndim == 2 else -1
    if (pv.ndim != 2 or pv.shape[1] != VOXELS_PER_BLOCK or pv.dtype.kind not in "iu" or pw.shape != pv.shape
            or pw.dtype.kind not in "iu" or pc.ndim != 3 or pc.shape[1:] != (VOXELS_PER_BLOCK, 3)
            or pc.shape[0] not in (0, n)):
        raise VolumeError(f"{path}: voxel pools are {pv.shape}, {pw.shape}, {pc.shape}, expected (n, "
                          f"{VOXELS_PER_BLOCK}), (n, {VOXELS_PER_BLOCK}) and (n or 0, {VOXELS_PER_BLOCK}, 3)")
    if idx.size and (int(idx.min()) < -1 or int(idx.max()) >= n):
        raise VolumeError(f"{path}: block table points at pool rows {int(idx.min())}..{int(idx.max())}, but the "
                          f"pools hold {n} rows")
    _check_pool_values(path, int(meta["max_weight"]), bw, pv, pw)


def _check_pool_values(path: Path, max_weight: int, bw: np.ndarray, pv: np.ndarray, pw: np.ndarray) -> None:
    """VolumeError naming the file and the array unless the distances are int16 (kinfu writes v * 32767 as int16;
    another type was cast to it silently, wrapping values outside int16) and the weights lie in [0, max_weight]
    (a weight above it was fused as if that many frames had been seen, and an int16 one wrapped in the uint8 cast)."""
    if pv.dtype != np.int16:
        raise VolumeError(f"{path}: 'pool_v' is {pv.dtype}, expected int16 (truncated distances times "
                          f"{2**15 - 1}, as kinfu writes them)")
    for name, w in (("block_w", bw), ("pool_w", pw)):
        if w.size and (int(w.min()) < 0 or int(w.max()) > max_weight):
            raise VolumeError(f"{path}: '{name}' holds weights {int(w.min())} to {int(w.max())}, expected 0 to the "
                              f"volume's max_weight {max_weight}")


def check_intrinsics(value, path) -> dict | None:
    """Recorded depth intrinsics (a mapping, or a sequence in INTRINSICS_KEYS order) checked: a dict of fx, fy,
    cx, cy (float) and width, height (int); None when absent; VolumeError naming the file when malformed."""
    if value is None:
        return None
    try:
        if not isinstance(value, dict):
            value = dict(zip(INTRINSICS_KEYS, np.asarray(value, dtype=np.float64).reshape(len(INTRINSICS_KEYS))))
        out = {k: float(value[k]) for k in INTRINSICS_KEYS}
    except (KeyError, TypeError, ValueError):
        raise VolumeError(f"{path}: 'intrinsics' is not fx, fy, cx, cy, width, height: {value!r}") from None
    if not (all(np.isfinite(v) for v in out.values()) and out["fx"] > 0 and out["fy"] > 0
            and out["width"] >= 1 and out["height"] >= 1):
        raise VolumeError(f"{path}: 'intrinsics' out of range: {value!r}")
    out["width"], out["height"] = int(out["width"]), int(out["height"])
    return out


def report_json_of(path: str | os.PathLike) -> dict | None:
    """The report.json of the `kinfu fuse` run beside a volume file (or in a fuse output folder), if any: what the
    volume's own meta does not hold (its recording, window, sensor), read for provenance and warnings; None when
    absent or not a JSON object."""
    p = Path(path)
    p = p / "report.json" if p.is_dir() else p.parent / "report.json"
    try:
        doc = json.loads(p.read_text())
    except (OSError, ValueError, RecursionError):
        return None
    return doc if isinstance(doc, dict) else None
