"""Changed voxels, cleaned of pose noise, grouped into change regions.

removed = occupied before and empty after; added = empty before and occupied after. A voxel unknown in either
volume is never a change (it is counted, so an empty answer caused by unobserved space can be reported: `hidden`
counts the voxels occupied in one volume that lie, by the same cleaning, deep in the other's unknown space, in
blobs as large as a region).

Pose noise: two fusions of one unchanged surface disagree by up to a voxel or so, which would outline every
surface with a thin sheet of "changes". We erode the free space, not the change mask: a voxel counts as removed
only when the after volume is empty in its whole 3x3x3 neighbourhood (`margin` such steps: a binary erosion of
the free space with the 26-neighbourhood), and as added only when the before volume is empty all around it. So a
change must lie at least `margin` voxels from every surface of the other volume, which is what a pose error of
`margin` voxels can shift. A binary opening of the change mask was rejected: it removes every change thinner
than three voxels, and the occupied band a TSDF keeps behind a surface (truncation / voxel size voxels, often
2-3) is exactly that thin, so a real removed object would vanish with the noise.

Depth noise (change/noise.py): far from the cameras two fusions of one surface disagree by more than pose noise;
with `margin_of`, a voxel must also be empty all around within its own margin (`empty_within`), and the voxels
that pass the fixed margin but not their own are counted (`within_noise`).

Regions: 26-connected components of each kind (what scipy.ndimage.label gives with a 3x3x3 structure); components smaller than `min_voxels`
are dropped as noise (counted).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN
from kinfu_cli.core.point_pairs import pair_components

KINDS = ("removed", "added")


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
    hidden: dict[str, int]  # of those, voxels in blobs of min_voxels or more deep in the other's unknown space
    regions: list[Region]
    dropped_regions: int
    dropped_voxels: int
    within_noise: dict[str, int] | None = None  # voxels past the fixed margin but within their depth-noise margin
    # of those, the clusters of min_voxels or more: regions but for the depth noise (a real change may hide there)
    within_noise_regions: list[Region] = field(default_factory=list)


def empty_all_around(labels: np.ndarray, idx: np.ndarray, margin: int, label=EMPTY) -> np.ndarray:
    """(N,) bool: voxel idx (N, 3) of `labels` is empty (`label`) and so is every voxel within `margin` steps of the
    26-neighbourhood, i.e. within the (2 margin + 1)^3 cube around it; outside the array counts as not empty.

    The same as scipy.ndimage.binary_erosion(labels == EMPTY, 3x3x3 cube, iterations=margin, border_value=0) read
    at idx (tests/change check it against scipy), but evaluated at the changed voxels only: they are a few
    thousand in a grid of 10^8, so this is seconds faster than eroding the dense grid.
    """
    idx = np.asarray(idx, dtype=np.int64).reshape(-1, 3)
    shape = np.array(labels.shape, dtype=np.int64)
    ok = np.ones(len(idx), dtype=bool)
    steps = np.arange(-margin, margin + 1)
    for off in np.array(np.meshgrid(steps, steps, steps, indexing="ij")).reshape(3, -1).T:
        q = idx + off
        inside = np.all((q >= 0) & (q < shape), axis=1)
        qc = np.clip(q, 0, shape - 1)
        ok &= inside & (labels[qc[:, 0], qc[:, 1], qc[:, 2]] == label)
    return ok


def _shell(m: int) -> np.ndarray:
    """Offsets at Chebyshev distance exactly m (the surface of the (2m+1)^3 cube)."""
    r = np.arange(-m, m + 1)
    offs = np.array(np.meshgrid(r, r, r, indexing="ij")).reshape(3, -1).T
    return offs[np.abs(offs).max(axis=1) == m]


def empty_within(labels: np.ndarray, idx: np.ndarray, margins: np.ndarray, start: int = 0,
                 label=EMPTY) -> np.ndarray:
    """(N,) bool: `empty_all_around(labels, idx[i], margins[i])` for each voxel, its own margin each, checking
    shell after shell (Chebyshev distance start+1, start+2, ...) on the voxels still in question; `start`: the
    margin already known to hold for all of them."""
    idx = np.asarray(idx, dtype=np.int64).reshape(-1, 3)
    margins = np.asarray(margins, dtype=np.int64).reshape(-1)
    shape = np.array(labels.shape, dtype=np.int64)
    ok = np.ones(len(idx), dtype=bool)
    if start == 0:
        ok = labels[tuple(idx.T)] == label if len(idx) else ok
    for m in range(start + 1, int(margins.max(initial=0)) + 1):
        ask = np.flatnonzero(ok & (margins >= m))
        if ask.size == 0:
            break
        q0, good = idx[ask], np.ones(len(ask), dtype=bool)
        for off in _shell(m):
            q = q0 + off
            inside = np.all((q >= 0) & (q < shape), axis=1)
            qc = np.clip(q, 0, shape - 1)
            good &= inside & (labels[qc[:, 0], qc[:, 1], qc[:, 2]] == label)
        ok[ask] = good
    return ok


def components(idx: np.ndarray) -> list[np.ndarray]:
    """26-connected components of voxel indices (N, 3), as index arrays.

    The same partition as scipy.ndimage.label with a 3x3x3 structure (tests/change check it), computed on a graph
    over the changed voxels (neighbours: Chebyshev distance 1, a k-d tree) rather than by labelling the dense box
    around them, which spans most of a room-sized grid when noise speckles are spread over it.
    """
    idx = np.asarray(idx, dtype=np.int64).reshape(-1, 3)
    if len(idx) == 0:
        return []
    pairs = cKDTree(idx).query_pairs(r=1.0, p=np.inf, output_type="ndarray")
    lab = pair_components(len(idx), pairs)
    n = int(lab.max()) + 1
    order = np.argsort(lab, kind="stable")
    return np.split(idx[order], np.cumsum(np.bincount(lab, minlength=n))[:-1])


def find_changes(before: np.ndarray, after: np.ndarray, margin: int = 1, min_voxels: int = 1,
                 margin_of: Callable[[np.ndarray], np.ndarray] | None = None) -> ChangeMasks:
    """Removed and added regions between two label arrays of one shape (see the module docstring); margin_of:
    voxel indices (N, 3) -> (N,) margins in voxels for the depth noise there (None: `margin` everywhere)."""
    raw_masks = {"removed": (before == OCCUPIED) & (after == EMPTY), "added": (before == EMPTY) & (after == OCCUPIED)}
    raw = {k: int(np.count_nonzero(m)) for k, m in raw_masks.items()}
    unknown, hidden = {}, {}
    for key, mask, other in (("occupied_before_unknown_after", (before == OCCUPIED) & (after == UNKNOWN), after),
                             ("occupied_after_unknown_before", (before == UNKNOWN) & (after == OCCUPIED), before)):
        idx = np.argwhere(mask)  # what could be a change the other volume never saw: the same cleaning
        unknown[key] = len(idx)
        hidden[key] = sum(len(c) for c in components(idx[empty_all_around(other, idx, margin, UNKNOWN)])
                          if len(c) >= min_voxels)
    kept = {k: 0 for k in KINDS}
    within_noise = None if margin_of is None else {k: 0 for k in KINDS}
    regions: list[Region] = []
    noise_regions: list[Region] = []
    dropped_regions = dropped_voxels = 0
    for kind, other in (("removed", after), ("added", before)):
        idx = np.argwhere(raw_masks[kind])
        idx = idx[empty_all_around(other, idx, margin)]
        if margin_of is not None and len(idx):
            ok = empty_within(other, idx, np.maximum(margin_of(idx), margin), start=margin)
            within_noise[kind] = int(np.count_nonzero(~ok))
            noise_regions += [Region(kind, c) for c in components(idx[~ok]) if len(c) >= min_voxels]
            idx = idx[ok]
        kept[kind] = len(idx)
        for vox in components(idx):
            if len(vox) >= min_voxels:
                regions.append(Region(kind, vox))
            else:
                dropped_regions += 1
                dropped_voxels += len(vox)
    regions.sort(key=lambda r: (-len(r.voxels), KINDS.index(r.kind), tuple(r.voxels.min(axis=0))))
    return ChangeMasks(raw, kept, unknown, hidden, regions, dropped_regions, dropped_voxels, within_noise,
                       noise_regions)
