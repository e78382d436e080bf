"""POIs scored against a diff's changes only where the diff could see a change: inside the common box.

score_change_pois (evaluation.changes) scores every POI it is given. A POI outside the common box (one grid is
smaller or shifted) that no region is near would count as a false positive, though a change it points at could
lie there unseen: such POIs are left unscored, counted and named in a warning (one that does reach a region is
a true positive wherever it stands). A POI farther than the match radius outside both grids cannot be of this
place (another frame, another scene): refused, as `kinfu nbv` refuses a POI outside its volume. A ratio whose
denominator is 0 (no POI scored: precision; no region: recall) is null with a warning, not 0.0, which would read
as "all wrong".
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.change.diff import ChangeResult
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.pois import Poi
from kinfu_cli.evaluation.changes import poi_change_distances, score_change_pois
from kinfu_cli.evaluation.poi import MATCH_RADIUS


def _check_near_volumes(result: ChangeResult, xyz: np.ndarray, pois: list[Poi], radius: float, named: str) -> None:
    """VolumeError naming the file and the first POI farther than `radius` outside both grids: no change either
    volume could hold is within the match radius of it."""
    boxes = result.grid_boxes or {}
    if not boxes or not len(xyz):
        return
    gap = np.min([np.linalg.norm(np.maximum(np.maximum(lo - xyz, xyz - hi), 0.0), axis=1)
                  for lo, hi in boxes.values()], axis=0)
    far = np.flatnonzero(gap > radius)
    if far.size:
        k = int(far[0])
        c = xyz[k]
        grids = "; ".join(f"{name} {np.round(lo, 3).tolist()}..{np.round(hi, 3).tolist()} m"
                          for name, (lo, hi) in zip((result.before, result.after), boxes.values()))
        more = f" ({far.size} POIs are)" if far.size > 1 else ""
        raise VolumeError(f"{named}: POI {pois[k].id} at ({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}) is {gap[k]:.2f} m "
                          f"outside both volumes{more}, farther than the match radius {radius:g} m ({grids}); "
                          f"expected POIs of the volumes' place, in their frame")


def score_pois_in_comparison(result: ChangeResult, pois: list[Poi], radius: float = MATCH_RADIUS,
                             source: str = "") -> dict:
    """score_change_pois on the POIs the diff can judge (see the module docstring), stored as `result.pois` with
    `pois` (all in the file), `pois_scored`, `pois_outside_common_box` and per POI `scored`; its warnings are
    added to `result.warnings`. VolumeError for a POI far outside both volumes."""
    named = source or "pois"
    xyz = np.array([p.position for p in pois], dtype=np.float64).reshape(-1, 3)
    _check_near_volumes(result, xyz, pois, radius, named)
    # half a voxel of slack: a POI on the box's face is as near to the compared voxels as one just inside
    inside = result.pair.contains(xyz, tolerance=result.pair.voxel_size / 2)
    reaches = (poi_change_distances(xyz, result.regions) < radius).any(axis=1)
    scored = inside | reaches
    doc = score_change_pois(result, [p for p, s in zip(pois, scored) if s], radius=radius, source=source)
    per_poi = iter(doc["per_poi"])
    doc["per_poi"] = [{**next(per_poi), "scored": True} if s else
                      {"id": int(p.id), "position": [float(v) for v in p.position], "nearest_region": None,
                       "distance_m": None, "true_positive": False, "scored": False} for p, s in zip(pois, scored)]
    outside = [int(p.id) for p, s in zip(pois, scored) if not s]
    doc.update(pois=len(pois), pois_scored=int(scored.sum()), pois_outside_common_box=len(outside))
    warnings = []
    if not pois:
        warnings.append(f"{named}: the file holds no POI: nothing to score, precision and F1 are undefined (null)")
    elif outside:
        ids = ", ".join(map(str, outside[:10])) + (", ..." if len(outside) > 10 else "")
        warnings.append(f"{named}: {len(outside)} of {len(pois)} POIs (id {ids}) lie outside the common box of the "
                        f"two grids and near no region: not scored (a change they point at could lie where the "
                        f"volumes were not compared)")
        if not doc["pois_scored"]:
            warnings.append(f"{named}: no POI lies where the volumes were compared: precision and F1 are undefined "
                            f"(null)")
    if not doc["pois_scored"]:
        doc["precision"] = None
    if not doc["changes"]:
        warnings.append(f"{named}: no change region was found, so recall and F1 are undefined (null), not 0")
        doc["recall"] = None
    if doc["precision"] is None or doc["recall"] is None:
        doc["f1"] = None
    result.pois = doc
    result.warnings += warnings
    return doc


__all__ = ["score_pois_in_comparison"]
