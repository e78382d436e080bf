"""Two ternary grids of one place brought onto one lattice: the part of space both cover.

The before grid's lattice is the reference. Each of its voxel centres inside the after grid takes the label of
the after voxel holding it, which is the after voxel whose centre is nearest (same voxel size, so nearest-voxel
resampling never blends labels). Grids of different voxel sizes are refused rather than resampled: a coarser
grid's occupied voxel would smear over several finer ones and look like a change.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import UNKNOWN, TernaryGrid

#: Relative difference of voxel sizes still taken as equal (float round-off of stored sizes).
VOXEL_SIZE_TOLERANCE = 1e-6


@dataclass
class AlignedPair:
    """The labels of both volumes on the common box (same shape), on the before grid's lattice.

    origin: world position of the common box's minimum corner; offset: where the box starts in the before
    grid (voxel index); observed_*: voxels known (occupied or empty) in each whole grid; observed_both: voxels
    of the common box known in both; in_box_*: voxels of the common box known in each (the rest of a volume's
    observed voxels lie outside the other's grid, where nothing of it is compared).
    """

    before: np.ndarray
    after: np.ndarray
    origin: np.ndarray
    voxel_size: float
    offset: np.ndarray
    observed_before: int
    observed_after: int
    observed_both: int
    in_box_before: int
    in_box_after: int

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(s) for s in self.before.shape)  # type: ignore[return-value]

    @property
    def overlap(self) -> float:
        """Voxels known in both over the known voxels of the volume that knows fewer (1 = one holds the other)."""
        least = min(self.observed_before, self.observed_after)
        return self.observed_both / least if least else 0.0

    def in_box_fraction(self, which: str) -> float:
        """Share of the `which` ("before" | "after") volume's observed voxels that lie in the common box."""
        observed = getattr(self, f"observed_{which}")
        return getattr(self, f"in_box_{which}") / observed if observed else 0.0

    def compared_fraction(self, which: str) -> float:
        """Share of the `which` volume's observed voxels that are known in both (the voxels compared)."""
        observed = getattr(self, f"observed_{which}")
        return self.observed_both / observed if observed else 0.0

    def contains(self, points: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
        """(N,) bool: world points (N, 3) inside the common box grown by `tolerance` metres."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        hi = self.origin + np.array(self.shape) * self.voxel_size
        return np.all((p >= self.origin - tolerance) & (p <= hi + tolerance), axis=1)

    def centers(self, idx: np.ndarray) -> np.ndarray:
        """World centres (N, 3) of voxel indices of the common box."""
        return self.origin + (np.asarray(idx, dtype=np.float64) + 0.5) * self.voxel_size


def align(before: TernaryGrid, after: TernaryGrid, before_name: str = "before",
          after_name: str = "after") -> AlignedPair:
    """Both grids on the common box; VolumeError naming the files when the voxel sizes differ or the grids
    share no voxel."""
    vs = before.voxel_size
    if abs(after.voxel_size - vs) > VOXEL_SIZE_TOLERANCE * vs:
        raise VolumeError(f"{after_name}: voxel size {after.voxel_size:g} m, but {before_name} has {vs:g} m; "
                          f"fuse both with one voxel size")
    ranges, picks = [], []
    for axis in range(3):
        centres = before.origin[axis] + (np.arange(before.shape[axis]) + 0.5) * vs
        j = np.floor((centres - after.origin[axis]) / vs + 1e-9).astype(np.int64)
        inside = np.flatnonzero((j >= 0) & (j < after.shape[axis]))
        if inside.size == 0:
            lo_b, hi_b = before.origin, before.origin + np.array(before.shape) * vs
            lo_a, hi_a = after.origin, after.origin + np.array(after.shape) * vs
            raise VolumeError(f"{after_name}: its grid {np.round(lo_a, 3).tolist()}..{np.round(hi_a, 3).tolist()} m "
                              f"does not overlap {before_name}'s {np.round(lo_b, 3).tolist()}.."
                              f"{np.round(hi_b, 3).tolist()} m; expected two volumes of the same place")
        ranges.append((int(inside[0]), int(inside[-1]) + 1))
        picks.append(j[inside[0]:inside[-1] + 1])
    (x0, x1), (y0, y1), (z0, z1) = ranges
    b = before.labels[x0:x1, y0:y1, z0:z1]
    # equal voxel sizes: consecutive before voxels fall in consecutive after voxels, so the pick is a slice (a view)
    contiguous = all(np.array_equal(j, np.arange(j[0], j[0] + len(j))) for j in picks)
    a = (after.labels[tuple(slice(int(j[0]), int(j[-1]) + 1) for j in picks)] if contiguous
         else after.labels[np.ix_(*picks)])
    offset = np.array([x0, y0, z0], dtype=np.int64)
    return AlignedPair(before=b, after=a, origin=before.origin + offset * vs, voxel_size=vs, offset=offset,
                       observed_before=int(np.count_nonzero(before.labels != UNKNOWN)),
                       observed_after=int(np.count_nonzero(after.labels != UNKNOWN)),
                       observed_both=int(np.count_nonzero((b != UNKNOWN) & (a != UNKNOWN))),
                       in_box_before=int(np.count_nonzero(b != UNKNOWN)),
                       in_box_after=int(np.count_nonzero(a != UNKNOWN)))
