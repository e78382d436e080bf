"""Gain functions: how much a view is expected to reveal of the region S(POI).

All gains are sums over the view's pixels of a per-ray term computed by the ray caster
(`raycast.py`), restricted to voxels whose centre is inside S and at least `min_range` away:

- ``unknown`` (the paper, Monica et al. RAS 2016 eq. 10): number of rays whose first non-empty voxel
  is unknown and inside S.
- ``distance``: the same rays, each weighted by 1 / t^2 (t = distance of the hit in metres), since a
  structured-light depth error grows with distance; prefers close views of the unknown region.
- ``rear``: rays that, continuing through unknown space, meet an occupied voxel right after an unknown
  voxel inside S -- the view looks at the hidden rear side of a surface already seen (the "rear side
  voxel" gain compared by Delmerico et al., Autonomous Robots 2018).
- ``entropy``: occlusion-aware expected information (Isler et al., ICRA 2016): each ray sums, over the
  unknown voxels in S it crosses before the first occupied voxel, P_visible * H(p_unknown), where
  P_visible = (1 - p_unknown)^(unknown voxels crossed before); known voxels (occupied or empty) carry
  no entropy in a ternary map. With p_unknown = 0.5 a ray contributes at most 2 bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinfu_cli.core.errors import ConfigError


@dataclass(frozen=True)
class Gain:
    """A gain function: `term` indexes the per-ray terms of `raycast`; `through` = rays continue
    through unknown voxels (slower)."""

    name: str
    term: int
    through: bool
    unit: str
    description: str


GAINS: dict[str, Gain] = {
    "unknown": Gain("unknown", 0, False, "rays",
                    "rays stopping on an unknown voxel inside S(POI) (the paper's gain)"),
    "distance": Gain("distance", 1, False, "rays/m^2",
                     "rays stopping on an unknown voxel inside S(POI), weighted by 1/distance^2"),
    "rear": Gain("rear", 2, True, "rays",
                 "rays reaching an occupied voxel right behind unknown voxels inside S(POI) (rear side)"),
    "entropy": Gain("entropy", 3, True, "bits",
                    "occlusion-aware entropy of the unknown voxels inside S(POI) along each ray (Isler 2016)"),
}


def gain_names() -> tuple[str, ...]:
    """The names `get_gain` accepts, in a fixed order (the paper's first)."""
    return tuple(GAINS)


def get_gain(name: str) -> Gain:
    """The gain called `name`; a ConfigError naming the parameter `gain` otherwise."""
    try:
        return GAINS[name]
    except KeyError:
        raise ConfigError(f"expected one of {', '.join(GAINS)}, got {name!r}", parameter="gain") from None


def all_gain_values(terms: np.ndarray, through: bool) -> dict[str, np.ndarray]:
    """Every gain computable from `terms` (the `through` ones only when the rays went through)."""
    return {n: np.asarray(terms)[:, g.term].copy() for n, g in GAINS.items() if through or not g.through}
