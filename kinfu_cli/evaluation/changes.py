"""Hand-derived POIs scored against the changes a volume diff found, with the paper's rule (RAS 2016 Sec. 6.2):
a POI within 0.20 m of a change is a true positive, else a false positive; a change with no POI within 0.20 m
is a false negative. The distance of a POI to a change is to the change's nearest voxel centre (the paper
measures to the changed object, not to its centre: a POI on the rim of a large moved box is right). This closes
the attention loop end to end without hand labels: the diff of the volumes before and after is the label.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.change.diff import ChangeResult
from kinfu_cli.core.pois import Poi
from kinfu_cli.evaluation.poi import MATCH_RADIUS, score_matches


def poi_change_distances(pois_xyz: np.ndarray, regions: list) -> np.ndarray:
    """(K, M) distance of each POI to the nearest voxel centre of each region (regions have `.points`)."""
    p = np.asarray(pois_xyz, dtype=np.float64).reshape(-1, 3)
    d = np.full((len(p), len(regions)), np.inf)
    for m, r in enumerate(regions):
        if len(p) and len(r.points):
            d[:, m] = cKDTree(r.points).query(p)[0]
    return d


def score_change_pois(result: ChangeResult, pois: list[Poi], radius: float = MATCH_RADIUS,
                      source: str = "") -> dict:
    """Precision, recall and F1 of `pois` against `result`'s regions; also stored as `result.pois`."""
    xyz = np.array([p.position for p in pois], dtype=np.float64).reshape(-1, 3)
    d = poi_change_distances(xyz, result.regions)
    tp, fp, fn = score_matches(d < radius)
    changes = len(result.regions)
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = (changes - fn) / changes if changes else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    per_poi = []
    for k, p in enumerate(pois):
        m = int(np.argmin(d[k])) if changes else None
        dist = float(d[k, m]) if m is not None else None
        per_poi.append({"id": int(p.id), "position": [float(v) for v in p.position],
                        "nearest_region": result.regions[m].id if m is not None else None,
                        "distance_m": round(dist, 4) if dist is not None else None,
                        "true_positive": bool(dist is not None and dist < radius)})
    missed = [result.regions[m].id for m in range(changes) if not (d[:, m] < radius).any()]
    doc = {"source": source, "radius": radius, "pois": len(pois), "changes": changes, "tp": tp, "fp": fp, "fn": fn,
           "precision": precision, "recall": recall, "f1": f1, "per_poi": per_poi, "missed_regions": missed}
    result.pois = doc
    return doc
