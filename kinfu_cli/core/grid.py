"""The ternary voxel map (occupied / unknown / empty) shared by fusion, NBV and segmentation.

File contract (`ternary.npz`, as ros_kinfu exports): array `ternary` int8, indexed [x, y, z],
1 = occupied, 0 = unknown, -1 = empty; `origin` (3,) world position of the grid's minimum
corner, so voxel (i, j, k) has its centre at origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_size;
`voxel_size` (metres); optional `frame` (str): name of the world frame ("" or absent when not known);
optional `up` (3,) float64: the unit direction against gravity in that frame (absent when not known);
optional `intrinsics` (6,) float64: fx, fy, cx, cy, width, height of the depth camera fused (absent when not
known), so `kinfu nbv` on a ternary.npz plans with the camera that made it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import write_npz
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.memory import check_grid_memory
from kinfu_cli.core.volume_file import (INTRINSICS_KEYS, MAX_COORDINATE_M, MIN_VOXEL_M, READ_ERRORS, check_intrinsics,
                                        check_npz, npz_member_header)

OCCUPIED = np.int8(1)
UNKNOWN = np.int8(0)
EMPTY = np.int8(-1)


@dataclass
class TernaryGrid:
    """Labels (X, Y, Z) int8 in {1, 0, -1} on a regular grid."""

    labels: np.ndarray
    origin: np.ndarray
    voxel_size: float
    frame: str = ""  # world frame name, "" when not known
    up: np.ndarray | None = None  # unit "up" direction in the world frame (against gravity), None when not known
    intrinsics: dict | None = None  # depth camera fused: fx, fy, cx, cy, width, height; None when not known

    def __post_init__(self) -> None:
        self.labels = np.asarray(self.labels, dtype=np.int8)
        if self.up is not None:
            self.up = check_up(self.up)
        self.origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        self.voxel_size = float(self.voxel_size)
        if self.labels.ndim != 3:
            raise VolumeError(f"ternary labels must be 3-D, got shape {self.labels.shape}")
        if not self.voxel_size > 0:
            raise VolumeError(f"voxel_size must be positive, got {self.voxel_size}")

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.labels.shape)  # type: ignore[return-value]

    def centers(self, idx: np.ndarray) -> np.ndarray:
        """World centres of voxel indices (N, 3)."""
        return self.origin + (np.asarray(idx, dtype=np.float64) + 0.5) * self.voxel_size

    def index_of(self, points: np.ndarray) -> np.ndarray:
        """Integer voxel indices (N, 3) of world points (may be out of range)."""
        return np.floor((np.asarray(points, dtype=np.float64) - self.origin) / self.voxel_size).astype(np.int64)

    def labels_at(self, points: np.ndarray) -> np.ndarray:
        """int8 (N,) labels at world points (N, 3); points outside the grid were never observed: UNKNOWN."""
        return labels_at_indices(self.labels, self.index_of(np.asarray(points).reshape(-1, 3)))

    def counts(self) -> dict[str, int]:
        """Number of occupied / unknown / empty voxels."""
        flat = self.labels.ravel()
        occ = int(np.count_nonzero(flat == OCCUPIED))
        emp = int(np.count_nonzero(flat == EMPTY))
        return {"occupied": occ, "empty": emp, "unknown": int(flat.size - occ - emp)}


def check_up(up, parameter: str = "up") -> np.ndarray:
    """`up` as a unit float64 (3,) vector; ConfigError naming `parameter` for a non-finite or zero vector."""
    try:
        v = np.asarray(up, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ConfigError(f"expected three numbers x,y,z, got {up!r}", parameter=parameter) from None
    big = float(np.max(np.abs(v))) if np.all(np.isfinite(v)) else 0.0
    if not big > 1e-9:  # (NaN, inf and zero vectors; a tiny but non-zero one has no reliable direction either)
        raise ConfigError(f"expected a finite non-zero direction x,y,z, got {v.tolist()}", parameter=parameter)
    v = v / big  # first to [-1, 1]: the norm of (1e300, 1e300, 0) overflows
    return v / float(np.linalg.norm(v))


# the coarsest voxel of a ternary file read (segment then names a voxel too coarse to segment; a volume.npz's
# limit is a depth sensor's range, 100 m)
MAX_GRID_VOXEL_M = 1e3


def save_ternary(path: str | os.PathLike, grid: TernaryGrid) -> None:
    """Write `ternary.npz` atomically (compressed: mostly-constant labels shrink a lot)."""
    arrays = {"ternary": grid.labels, "origin": grid.origin, "voxel_size": np.float64(grid.voxel_size),
              "frame": np.array(grid.frame)}
    if grid.up is not None:
        arrays["up"] = grid.up
    if grid.intrinsics is not None:
        arrays["intrinsics"] = np.array([grid.intrinsics[k] for k in INTRINSICS_KEYS], dtype=np.float64)
    write_npz(path, arrays)


def read_ternary(path: str | os.PathLike) -> TernaryGrid | None:
    """The grid of a `ternary.npz`; None when `path` is a readable .npz without a 'ternary' array (such as a
    fusion volume.npz, which fusion's `load_grid` reads); VolumeError naming the file when it is missing,
    unreadable (truncated, corrupt) or its arrays break the file contract (labels other than 1 / 0 / -1, a
    non-finite or far-away origin, a voxel size that is not a positive length, a bad up direction)."""
    path = Path(path)
    if not path.exists():
        raise VolumeError(f"{path}: no such file")
    check_npz(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            keys = set(data.files)
            if "ternary" not in keys:
                return None
            missing = [k for k in ("origin", "voxel_size") if k not in keys]
            if missing:
                raise VolumeError(f"{path}: ternary.npz lacks the arrays {', '.join(missing)}")
            _check_labels_memory(path, *npz_member_header(data, "ternary"))
            labels, origin, voxel_size = data["ternary"], data["origin"], data["voxel_size"]
            frame = data["frame"] if "frame" in keys else np.array("")
            up = data["up"] if "up" in keys else None
            intrinsics = data["intrinsics"] if "intrinsics" in keys else None
    except VolumeError:
        raise
    except READ_ERRORS as exc:
        text = str(exc).replace("\n", " ").strip()[:160] or type(exc).__name__
        raise VolumeError(f"{path}: not a readable .npz volume ({text}); it may be truncated or corrupt") from None
    if labels.ndim != 3 or labels.dtype.kind not in "iu" or (labels.size and (
            int(labels.min()) < -1 or int(labels.max()) > 1)):
        raise VolumeError(f"{path}: 'ternary' is {labels.dtype} {labels.shape}, expected a 3-D integer array of "
                          f"1 (occupied), 0 (unknown), -1 (empty)")
    if origin.shape != (3,) or origin.dtype.kind not in "iuf" or not (
            np.all(np.isfinite(origin)) and np.abs(origin).max() <= MAX_COORDINATE_M):
        raise VolumeError(f"{path}: 'origin' is {origin.tolist()!r}, expected three finite coordinates within "
                          f"{MAX_COORDINATE_M:g} m")
    if voxel_size.size != 1 or voxel_size.dtype.kind not in "iuf" or not (
            MIN_VOXEL_M <= float(voxel_size) <= MAX_GRID_VOXEL_M):
        raise VolumeError(f"{path}: 'voxel_size' is {voxel_size.tolist()!r}, expected a voxel edge of "
                          f"{MIN_VOXEL_M:g} to {MAX_GRID_VOXEL_M:g} m")
    if frame.shape != () or frame.dtype.kind != "U":
        raise VolumeError(f"{path}: 'frame' is not a frame name")
    intrinsics = check_intrinsics(intrinsics, path)
    try:
        return TernaryGrid(labels, origin, float(voxel_size), str(frame), up, intrinsics)
    except ConfigError as exc:  # the up direction
        raise VolumeError(f"{path}: 'up' {exc.detail}") from None


# what a stage holds per voxel besides the labels: one voxel-sized mask (of the occupied, empty or unknown voxels);
# segment on a 2048^3 grid (8 GiB of labels) peaked at 16.9 GB
WORK_BYTES_PER_VOXEL = 1


def _check_labels_memory(path: Path, shape: tuple[int, ...], dtype: np.dtype) -> None:
    """VolumeError naming the file, its grid and the memory needed when the labels array as stored, its int8 copy
    (for another integer type) and a voxel-sized mask would not fit, as for a volume.npz's grid (TernaryVolume):
    checked on the .npy header, before anything is decompressed (a 2048^3 grid of 8 MB compressed was read for a
    minute, then held 9 GB in nbv and 17 GB in segment)."""
    voxels = math.prod(shape)
    need = voxels * (dtype.itemsize + (0 if dtype == np.int8 else 1) + WORK_BYTES_PER_VOXEL)
    check_grid_memory(need, f"{path}: ternary grid of {'x'.join(map(str, shape))} voxels",
                      "expected a grid that fits in memory (fuse with a coarser voxel size or a smaller size)")


def load_ternary(path: str | os.PathLike) -> TernaryGrid:
    """Read a `ternary.npz` (VolumeError for anything else; fusion's `load_grid` also takes a volume.npz)."""
    grid = read_ternary(path)
    if grid is None:
        raise VolumeError(f"{path}: expected a ternary.npz with arrays 'ternary', 'origin', 'voxel_size'")
    return grid


def labels_at_indices(labels: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """int8 (N,) of dense `labels` at voxel indices (N, 3); indices outside it read UNKNOWN."""
    inside = np.all((idx >= 0) & (idx < np.array(labels.shape)), axis=1)
    out = np.full(len(idx), UNKNOWN, dtype=np.int8)
    i = idx[inside]
    out[inside] = labels[i[:, 0], i[:, 1], i[:, 2]]
    return out
