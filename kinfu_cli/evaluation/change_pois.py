"""POIs scored against a diff's changes only where the diff could see a change: inside the common box, in space
both volumes observed.

score_change_pois (evaluation.changes) scores every POI it is given. A POI outside the common box (one grid is
smaller or shifted) that no region is near would count as a false positive, though a change it points at could
lie there unseen; so would a POI inside it whose surroundings one volume never observed (the later recording
never looked at that corner of the table), since the diff ignores voxels unknown in either volume. Such POIs
are left unscored, counted and named in a warning (one that does reach a region is a true positive wherever it
stands). A POI farther than the match radius outside both grids cannot be of this place (another frame, another
scene): refused, as `kinfu nbv` refuses a POI outside its volume. A ratio whose denominator is 0 (no POI scored:
precision; no region: recall) is null with a warning, not 0.0, which would read as "all wrong".
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.change.align import AlignedPair
from kinfu_cli.change.diff import ChangeResult
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import UNKNOWN
from kinfu_cli.core.pois import Poi
from kinfu_cli.evaluation.changes import poi_change_distances, score_change_pois
from kinfu_cli.evaluation.poi import MATCH_RADIUS

#: Below this share of the space within the match radius of a POI known in both volumes, the POI is not scored:
#: the diff compared too little there to call "no change" a miss. Around a POI on a tabletop both volumes saw,
#: 15-73 % is known in both (sample pair, 300 points on the table; solid interiors stay unknown in both, so ~70 %
#: is the most), ~4 % only on the room's floor at the grid's far edge; where the later recording never looked it is
#: 0 %, and it rises through 1-10 % at the edge of its view, where the other volume still knows 60-70 %.
MIN_KNOWN_SHARE = 0.10
#: Most lattice points a POI's ball is sampled at per axis: a large radius on a fine grid is sampled at a stride.
MAX_BALL_SIDE = 128


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


def known_shares(pair: AlignedPair, xyz: np.ndarray, radius: float) -> np.ndarray:
    """(K, 3) share of the voxel centres within `radius` of each POI known in both volumes, in before, in after.

    Voxels outside the common box count as unknown (nothing there was compared). Each POI's ball is one numpy
    slice of the common box (strided when wider than MAX_BALL_SIDE voxels); the nearest voxel always counts, so
    a radius under a voxel still reads the POI's own voxel."""
    vs = pair.voxel_size
    n = int(np.ceil(radius / vs))
    offsets = np.arange(-n, n + 1, max(1, int(np.ceil((2 * n + 1) / MAX_BALL_SIDE))))
    shape = np.array(pair.shape)
    out = np.zeros((len(xyz), 3))
    for k, q in enumerate(xyz):
        idx = np.floor((q - pair.origin) / vs).astype(np.int64)[:, None] + offsets  # (3, S) voxel indices per axis
        d = pair.origin[:, None] + (idx + 0.5) * vs - q[:, None]
        d2 = d[0][:, None, None] ** 2 + d[1][None, :, None] ** 2 + d[2][None, None, :] ** 2
        ball = (d2 <= radius ** 2) | (d2 == d2.min())
        inside = [(i >= 0) & (i < s) for i, s in zip(idx, shape)]
        known = np.zeros((2,) + ball.shape, dtype=bool)
        pick = np.ix_(*[i[m] for i, m in zip(idx, inside)])
        known[(slice(None),) + np.ix_(*inside)] = [pair.before[pick] != UNKNOWN, pair.after[pick] != UNKNOWN]
        known &= ball
        out[k] = np.count_nonzero(known[0] & known[1]), np.count_nonzero(known[0]), np.count_nonzero(known[1])
        out[k] /= np.count_nonzero(ball)
    return out


def _ids(ids: list[int]) -> str:
    return ", ".join(map(str, ids[:10])) + (", ..." if len(ids) > 10 else "")


def score_pois_in_comparison(result: ChangeResult, pois: list[Poi], radius: float = MATCH_RADIUS,
                             source: str = "") -> dict:
    """score_change_pois on the POIs the diff can judge (see the module docstring), stored as `result.pois` with
    `pois` (all in the file), `pois_scored`, `pois_outside_common_box`, `pois_unobserved`, `min_known_share` and
    per POI `scored`, `reason` (null, "outside_common_box" or "unobserved") and `known_share` (within `radius`,
    known in both); its warnings are added to `result.warnings`. VolumeError for a POI far outside both volumes."""
    named = source or "pois"
    xyz = np.array([p.position for p in pois], dtype=np.float64).reshape(-1, 3)
    _check_near_volumes(result, xyz, pois, radius, named)
    # half a voxel of slack: a POI on the box's face is as near to the compared voxels as one just inside
    inside = result.pair.contains(xyz, tolerance=result.pair.voxel_size / 2)
    reaches = (poi_change_distances(xyz, result.regions) < radius).any(axis=1)
    shares = known_shares(result.pair, xyz, radius)
    observed = shares[:, 0] >= MIN_KNOWN_SHARE
    scored = (inside & observed) | reaches
    reasons = [None if s else "outside_common_box" if not i else "unobserved"
               for s, i in zip(scored, inside)]
    doc = score_change_pois(result, [p for p, s in zip(pois, scored) if s], radius=radius, source=source)
    per_poi = iter(doc["per_poi"])
    doc["per_poi"] = [{**(next(per_poi) if s else
                          {"id": int(p.id), "position": [float(v) for v in p.position], "nearest_region": None,
                           "distance_m": None, "true_positive": False}),
                       "scored": bool(s), "reason": why, "known_share": round(float(share), 4)}
                      for p, s, why, share in zip(pois, scored, reasons, shares[:, 0])]
    outside = [int(p.id) for p, why in zip(pois, reasons) if why == "outside_common_box"]
    unobserved = [k for k, why in enumerate(reasons) if why == "unobserved"]
    doc.update(pois=len(pois), pois_scored=int(scored.sum()), pois_outside_common_box=len(outside),
               pois_unobserved=len(unobserved), min_known_share=MIN_KNOWN_SHARE)
    warnings = []
    if not pois:
        warnings.append(f"{named}: the file holds no POI: nothing to score, precision and F1 are undefined (null)")
    if outside:
        warnings.append(f"{named}: {len(outside)} of {len(pois)} POIs (id {_ids(outside)}) lie outside the common "
                        f"box of the two grids and near no region: not scored (a change they point at could lie "
                        f"where the volumes were not compared)")
    if unobserved:
        # name the volumes that never looked there: under the threshold on their own, else the one knowing less
        names = (result.before, result.after)
        lacking = dict.fromkeys(name for k in unobserved for name in
                                ([n for n, v in zip(names, shares[k, 1:]) if v < MIN_KNOWN_SHARE]
                                 or [names[int(np.argmin(shares[k, 1:]))]]))
        low, high = (f"{100 * v:.0f}" for v in (shares[unobserved, 0].min(), shares[unobserved, 0].max()))
        ids = _ids([int(pois[k].id) for k in unobserved])
        warnings.append(f"{named}: {len(unobserved)} of {len(pois)} POIs (id {ids}) lie where {' or '.join(lacking)}"
                        f" barely observed: {low if low == high else f'{low}-{high}'} % of the space within {radius:g} "
                        f"m of them is known in both volumes (under {100 * MIN_KNOWN_SHARE:.0f} %) and no region is "
                        f"near: not scored (the diff ignores voxels unknown in either volume, so it could not have "
                        f"seen a change there)")
    if pois and not doc["pois_scored"]:
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


__all__ = ["MIN_KNOWN_SHARE", "known_shares", "score_pois_in_comparison"]
