"""Changed voxels, cleaned of pose noise, grouped into change regions.

removed = occupied before and empty after; added = empty before and occupied after. A voxel unknown in either
volume is never a change (it is counted, so an empty answer caused by unobserved space can be reported).

Pose noise: two fusions of one unchanged surface disagree by up to a voxel or so, which would outline every
surface with a thin sheet of "changes". We erode the free space, not the change mask: a voxel counts as removed
only when the after volume is empty in its whole 3x3x3 neighbourhood (`margin` such steps; scipy.ndimage
binary_erosion with the 26-neighbourhood), and as added only when the before volume is empty all around it. So a
change must lie at least `margin` voxels from every surface of the other volume, which is what a pose error of
`margin` voxels can shift. A binary opening of the change mask was rejected: it removes every change thinner
than three voxels, and the occupied band a TSDF keeps behind a surface (truncation / voxel size voxels, often
2-3) is exactly that thin, so a real removed object would vanish with the noise.

Regions: 26-connected components (scipy.ndimage.label) of each kind; components smaller than `min_voxels`
are dropped as noise (counted).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN

KINDS = ("removed", "added")
_CUBE = np.ones((3, 3, 3), dtype=bool)


@dataclass
class Region:
    """One connected change: kind ("removed" | "added"), voxel indices (N, 3) in the common box."""

    kind: str
    voxels: np.ndarray


@dataclass
class ChangeMasks:
    """Counts of the cleaning steps and the surviving regions of both kinds, largest first."""

    raw: dict[str, int]  # changed voxels before the erosion, per kind
    kept: dict[str, int]  # after the erosion, per kind
    unknown_ignored: dict[str, int]  # occupied in one volume where the other is unknown
    regions: list[Region]
    dropped_regions: int
    dropped_voxels: int


def _crop(masks: list[np.ndarray], grow: int) -> tuple[slice, ...] | None:
    """The box of every True voxel of `masks`, grown by `grow` voxels (clipped); None when all are False."""
    any_mask = np.logical_or.reduce(masks)
    box = []
    for axis in range(3):
        others = tuple(a for a in range(3) if a != axis)
        hit = np.flatnonzero(any_mask.any(axis=others))
        if hit.size == 0:
            return None
        box.append(slice(max(0, int(hit[0]) - grow), min(any_mask.shape[axis], int(hit[-1]) + 1 + grow)))
    return tuple(box)


def _empty_all_around(labels: np.ndarray, margin: int) -> np.ndarray:
    """Empty voxels whose whole neighbourhood within `margin` steps (26-neighbourhood) is empty too; outside the
    array counts as not empty."""
    free = labels == EMPTY
    if margin <= 0:
        return free
    return ndimage.binary_erosion(free, structure=_CUBE, iterations=margin, border_value=0)


def find_changes(before: np.ndarray, after: np.ndarray, margin: int = 1, min_voxels: int = 1) -> ChangeMasks:
    """Removed and added regions between two label arrays of one shape (see the module docstring)."""
    raw_masks = {"removed": (before == OCCUPIED) & (after == EMPTY), "added": (before == EMPTY) & (after == OCCUPIED)}
    raw = {k: int(np.count_nonzero(m)) for k, m in raw_masks.items()}
    unknown = {"occupied_before_unknown_after": int(np.count_nonzero((before == OCCUPIED) & (after == UNKNOWN))),
               "occupied_after_unknown_before": int(np.count_nonzero((before == UNKNOWN) & (after == OCCUPIED)))}
    box = _crop(list(raw_masks.values()), margin + 1)
    kept = {k: 0 for k in KINDS}
    regions: list[Region] = []
    dropped_regions = dropped_voxels = 0
    if box is None:
        return ChangeMasks(raw, kept, unknown, regions, 0, 0)
    corner = np.array([s.start for s in box], dtype=np.int64)
    evidence = {"removed": (raw_masks["removed"][box], after[box]), "added": (raw_masks["added"][box], before[box])}
    for kind, (mask, other) in evidence.items():
        mask = mask & _empty_all_around(other, margin)
        kept[kind] = int(np.count_nonzero(mask))
        if not kept[kind]:
            continue
        lab, n = ndimage.label(mask, structure=_CUBE)
        idx = np.argwhere(lab)  # C order, so the labels below follow the voxels
        ids = lab[tuple(idx.T)]
        order = np.argsort(ids, kind="stable")
        sizes = np.bincount(ids, minlength=n + 1)[1:]
        groups = np.split(idx[order] + corner, np.cumsum(sizes)[:-1])
        for size, vox in zip(sizes, groups):
            if size >= min_voxels:
                regions.append(Region(kind, vox))
            else:
                dropped_regions += 1
                dropped_voxels += int(size)
    regions.sort(key=lambda r: (-len(r.voxels), KINDS.index(r.kind), tuple(r.voxels[0])))
    return ChangeMasks(raw, kept, unknown, regions, dropped_regions, dropped_voxels)
