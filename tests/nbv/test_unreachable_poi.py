"""A POI that no candidate view can see is not called reconstructed.

Before: `kinfu nbv` on a 2-frame `kinfu synth --frames 2` volume printed "best unknown gain 0.0 (IncTh 189.1):
reconstructed" for a POI whose S(POI) held 31762 unknown voxels: every valid view's rays stopped on unobserved
space before reaching it (the optimistic planner found a gain of 17797 there). No warning.
"""

import json

import numpy as np

from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, save_ternary
from kinfu_cli.nbv.viewpoints import SphereSpec
from kinfu_cli.nbv.workflow import NbvOptions, rank_poi_views

CAM = CameraModel(60.0, 60.0, 39.5, 29.5, 80, 60, min_range=0.3, max_range=3.0)
SPHERE = SphereSpec(lon_step=90, lat_step=45, roll_step=180)
POI = np.array([0.8, 0.8, 0.5])


def _files(tmp_path, box, shell):
    """A table in a 1.6 m cube with a box on it (unknown or occupied), optionally wrapped in a shell of never
    observed space 0.25-0.45 m from the POI (above the table): the scan saw the room, not the way to the box."""
    n, vs = 80, 0.02
    lab = np.full((n, n, n), EMPTY, np.int8)
    lab[:, :, :20] = UNKNOWN
    lab[:, :, 20] = OCCUPIED
    lab[36:44, 36:44, 21:29] = box
    if shell:
        c = (np.indices((n, n, n)).transpose(1, 2, 3, 0) + 0.5) * vs
        d = np.linalg.norm(c - POI, axis=-1)
        lab[(d > 0.25) & (d < 0.45) & (c[..., 2] > 0.42)] = UNKNOWN
    vol, pois = tmp_path / "ternary.npz", tmp_path / "pois.json"
    save_ternary(vol, TernaryGrid(lab, np.zeros(3), vs))
    pois.write_text(json.dumps({"pois": [{"id": 0, "position": POI.tolist(), "radius": 0.2}]}))
    return vol, pois


def _rank(tmp_path, box, shell):
    vol, pois = _files(tmp_path, box, shell)
    res = rank_poi_views(vol, pois, CAM, NbvOptions(sphere=SPHERE))
    return res, res.to_json()["pois"][0]


def test_a_poi_behind_unobserved_space_is_unreachable_not_reconstructed(tmp_path):
    res, p = _rank(tmp_path, UNKNOWN, shell=True)
    assert p["valid"] > 0 and p["best_gain"] == 0
    assert p["unreachable"] is True and p["reconstructed"] is False
    (w,) = res.warnings
    assert w.startswith("POI 0: no candidate view sees S(POI)") and "unknown voxels" in w


def test_a_visible_poi_keeps_the_papers_verdicts(tmp_path):
    (tmp_path / "a").mkdir()
    _, seen_unknown = _rank(tmp_path / "a", UNKNOWN, shell=False)
    assert seen_unknown["unreachable"] is False and seen_unknown["reconstructed"] is False
    assert seen_unknown["best_gain"] > seen_unknown["inc_th"]
    (tmp_path / "b").mkdir()
    res, known = _rank(tmp_path / "b", OCCUPIED, shell=False)
    assert known["unreachable"] is False and known["reconstructed"] is True and res.warnings == []


def test_quiet_prints_only_warnings(tmp_path):
    """`kinfu nbv --quiet` printed its ranking summary all the same; like fuse, segment and poi it prints only
    warnings and errors now (the views file is still written)."""
    from click.testing import CliRunner

    from kinfu_cli.cli import cli

    vol, pois = _files(tmp_path, UNKNOWN, shell=True)
    cam = ["--fx", "60", "--fy", "60", "--cx", "39.5", "--cy", "29.5", "--width", "80", "--height", "60",
           "--lon-step", "90", "--lat-step", "45", "--roll-step", "180"]
    loud = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "-o", str(tmp_path / "a.json"), *cam])
    quiet = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "-o", str(tmp_path / "b.json"), *cam,
                                     "--quiet"])
    assert loud.exit_code == quiet.exit_code == 0, loud.output + quiet.output
    assert "POI 0" in loud.stdout and quiet.stdout == ""
    assert "kinfu: warning: POI 0: no candidate view sees S(POI)" in quiet.stderr
    assert json.loads((tmp_path / "b.json").read_text())["pois"][0]["unreachable"] is True
