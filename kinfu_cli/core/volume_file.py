"""The fusion volume file (`volume.npz`): format name and version, writer and validating reader.

One .npz holding `meta` (a JSON string: format, format_version, shape, voxel_size, origin, truncation,
max_weight, min_depth, max_depth, color, block, frames_integrated, frame, and since the up direction and
intrinsics are recorded: up (unit [x, y, z] against gravity or null), up_source, intrinsics ({fx, fy, cx, cy,
width, height} of the depth camera fused, or null); readers treat missing ones as null) and the block-sparse arrays
`block_idx`, `block_w`, `pool_v`, `pool_w`, `pool_c` (see fusion/kernels.py for their meaning). The
reader checks format and version here so every stage reports a foreign file the same way; turning the
arrays back into a TernaryVolume is fusion's job (`fusion.volume.load_volume`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import write_npz
from kinfu_cli.core.errors import VolumeError

FORMAT = "kinfu-volume"
FORMAT_VERSION = 1
ARRAYS = ("block_idx", "block_w", "pool_v", "pool_w", "pool_c")


def write_volume_file(path: str | os.PathLike, meta: dict, arrays: dict[str, np.ndarray]) -> Path:
    """Write `meta` (JSON-able, with format and format_version) and the block arrays atomically."""
    return write_npz(path, {"meta": np.array(json.dumps(meta)), **{k: arrays[k] for k in ARRAYS}})


def read_volume_file(path: str | os.PathLike) -> tuple[dict, dict[str, np.ndarray]]:
    """(meta, arrays) of a volume.npz; VolumeError for a missing, unreadable, foreign or other-version file."""
    path = Path(path)
    if not path.exists():
        raise VolumeError(f"{path}: no such volume file")
    try:
        with np.load(path, allow_pickle=False) as data:
            if "meta" not in data.files:
                raise VolumeError(f"{path}: not a kinfu volume.npz (no 'meta' array; a ternary.npz cannot be "
                                  f"fused into)")
            meta = json.loads(str(data["meta"]))
            if meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
                raise VolumeError(f"{path}: volume format {meta.get('format')!r} version "
                                  f"{meta.get('format_version')!r}, expected {FORMAT!r} version {FORMAT_VERSION}")
            arrays = {k: data[k] for k in ARRAYS}
    except VolumeError:
        raise
    except (OSError, ValueError, EOFError, KeyError, json.JSONDecodeError) as exc:
        raise VolumeError(f"{path}: not a readable volume file ({exc})") from None
    return meta, arrays


def read_volume_meta(path: str | os.PathLike) -> dict | None:
    """The meta dict of a volume.npz without reading its arrays; None for an .npz without 'meta' (a
    ternary.npz); VolumeError for a missing or unreadable file."""
    path = Path(path)
    if not path.exists():
        raise VolumeError(f"{path}: no such volume file")
    try:
        with np.load(path, allow_pickle=False) as data:
            return json.loads(str(data["meta"])) if "meta" in data.files else None
    except (OSError, ValueError, EOFError, json.JSONDecodeError) as exc:
        raise VolumeError(f"{path}: not a readable volume file ({exc})") from None
