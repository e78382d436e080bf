"""The default IncTh (a number of rays) judges the paper's unknown gain, whatever gain ranks the views.

Before: `kinfu nbv scan/volume.npz --pois pois.json --gain rear` on the synthetic tabletop's scan said "best rear
gain 6.0 (IncTh 189.1): reconstructed" for a POI whose best unknown gain was 7055 rays ("not reconstructed" with
the default gain): the rear gain's scale was compared with a threshold in rays. A POI whose every view scored 0
on the chosen gain was ranked in candidate order, silently.
"""

import json

import numpy as np

from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.grid import EMPTY, UNKNOWN, TernaryGrid, save_ternary
from kinfu_cli.nbv.ranking import rank_poi
from kinfu_cli.nbv.viewpoints import SphereSpec
from kinfu_cli.nbv.workflow import NbvOptions, rank_poi_views

CAM = CameraModel(60.0, 60.0, 39.5, 29.5, 80, 60, min_range=0.3, max_range=3.0)
SPHERE = SphereSpec(lon_step=90, lat_step=45, roll_step=180)
POI = np.array([0.8, 0.8, 0.8])


def _floating_unknown() -> TernaryGrid:
    """An unknown 16 cm cube in empty space: much to see, no occupied surface behind it (rear gain 0)."""
    lab = np.full((80, 80, 80), EMPTY, np.int8)
    lab[36:44, 36:44, 36:44] = UNKNOWN
    return TernaryGrid(lab, np.zeros(3), 0.02)


def test_the_rear_gain_does_not_call_an_unseen_region_reconstructed():
    g = _floating_unknown()
    paper = rank_poi(g, POI, CAM, sphere=SPHERE)
    rear = rank_poi(g, POI, CAM, gain="rear", sphere=SPHERE)
    assert not paper.reconstructed and paper.best_gain > paper.inc_th
    assert rear.best_gain == 0 and rear.inc_th == paper.inc_th
    assert not rear.reconstructed and rear.extra["inc_th_gain"] == "unknown"
    given = rank_poi(g, POI, CAM, gain="rear", sphere=SPHERE, inc_th=1.0)  # a given IncTh judges the chosen gain
    assert given.reconstructed and given.extra["inc_th_gain"] == "rear"


def test_views_all_scoring_zero_are_a_warning(tmp_path):
    vol, pois = tmp_path / "t.npz", tmp_path / "pois.json"
    save_ternary(vol, _floating_unknown())
    pois.write_text(json.dumps({"pois": [{"id": 0, "position": POI.tolist(), "radius": 0.2}]}))
    res = rank_poi_views(vol, pois, CAM, NbvOptions(gain="rear", sphere=SPHERE))
    (w,) = res.warnings
    assert "every valid view scores 0 on the rear gain" in w
    assert rank_poi_views(vol, pois, CAM, NbvOptions(sphere=SPHERE)).warnings == []
