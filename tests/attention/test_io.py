"""Polhemus .traj reading (strict checks) and the pois.json contract."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinfu_cli.core.pois import Gaussian4, Poi, PoiFileError, read_pois, read_pois_document, write_pois
from kinfu_cli.core.errors import KinfuError, TrajectoryError
from kinfu_cli.io.polhemus import read_ground_truth, read_polhemus, write_polhemus
from kinfu_cli.io.trajectory import Trajectory


def _traj_text(mats) -> str:
    return "".join("\n".join(" ".join(f"{v:.6f}" for v in row) for row in m) + "\n\n" for m in mats)


def _rigid(n: int) -> np.ndarray:
    mats = np.tile(np.eye(4), (n, 1, 1))
    a = np.linspace(0, 1, n)
    mats[:, 0, 0] = mats[:, 1, 1] = np.cos(a)
    mats[:, 0, 1], mats[:, 1, 0] = -np.sin(a), np.sin(a)
    mats[:, :3, 3] = np.c_[a, 2 * a, 0.5 + 0 * a]
    return mats


def test_read_polhemus_times_positions_rotations(tmp_path):
    p = tmp_path / "a.traj"
    mats = _rigid(7)
    p.write_text(_traj_text(mats))
    tr = read_polhemus(p)
    assert len(tr) == 7
    np.testing.assert_allclose(tr.t, np.arange(7) / 100.0)
    np.testing.assert_allclose(tr.positions, mats[:, :3, 3], atol=1e-6)
    np.testing.assert_allclose(tr.rotations, mats[:, :3, :3], atol=1e-6)
    assert tr.source == str(p)


def test_write_then_read_roundtrip(tmp_path):
    tr = Trajectory(t=np.arange(5) / 100.0, positions=np.random.default_rng(0).normal(size=(5, 3)))
    p = write_polhemus(tmp_path / "b.traj", tr)
    back = read_polhemus(p)
    np.testing.assert_allclose(back.positions, tr.positions, atol=1e-5)


@pytest.mark.parametrize("case, expect", [
    ("empty", "empty trajectory file"),
    ("one", "1 sample"),
    ("nan", "sample 2 is not finite"),
    ("scaled", "sample 3 is not a rigid transform"),
    ("lastrow", "sample 1 is not a rigid transform: last row"),
    ("partial", "not a multiple of 16"),
    ("text", "sample 0 has a non-numeric value"),
])
def test_bad_traj_files_raise_one_line_errors(tmp_path, case, expect):
    mats = _rigid(5)
    p = tmp_path / f"{case}.traj"
    if case == "empty":
        p.write_text("\n\n")
    elif case == "one":
        p.write_text(_traj_text(mats[:1]))
    elif case == "nan":
        mats[2, 1, 3] = np.nan
        p.write_text(_traj_text(mats).replace("nan", "nan"))
    elif case == "scaled":
        mats[3, :3, :3] *= 1.2
        p.write_text(_traj_text(mats))
    elif case == "lastrow":
        mats[1, 3, 0] = 0.5
        p.write_text(_traj_text(mats))
    elif case == "partial":
        p.write_text(_traj_text(mats) + "1 2 3\n")
    elif case == "text":
        p.write_text(_traj_text(mats).replace("0.500000", "abc", 2))
    with pytest.raises(TrajectoryError) as exc:
        read_polhemus(p)
    msg = str(exc.value)
    assert expect in msg and str(p) in msg and "\n" not in msg


def test_missing_traj_file(tmp_path):
    with pytest.raises(TrajectoryError, match="no such trajectory file"):
        read_polhemus(tmp_path / "nope.traj")


def test_ground_truth_reader(tmp_path):
    p = tmp_path / "x.traj.res"
    p.write_text("0.56 0.03 1.37\n1.39 -0.06 1.33\n\n")
    np.testing.assert_allclose(read_ground_truth(p), [[0.56, 0.03, 1.37], [1.39, -0.06, 1.33]])
    p.write_text("0.56 0.03\n")
    with pytest.raises(TrajectoryError, match="line 1"):
        read_ground_truth(p)


def test_real_polhemus_file_reads(shared_data):
    d = shared_data("hand-polhemus", "pick_and_place")
    tr = read_polhemus(d / "user1_cup0.traj")
    gt = read_ground_truth(d / "user1_cup0.traj.res")
    assert gt.shape == (2, 3)
    assert len(tr) > 50 and np.all(np.isfinite(tr.positions))
    # the trajectory passes near both labelled changes (they were labelled on it)
    dmin = np.linalg.norm(tr.positions[:, None] - gt[None], axis=2).min(axis=0)
    assert np.all(dmin < 0.2)


def test_pois_json_roundtrip(tmp_path):
    g = Gaussian4(np.array([1.0, 2, 3, 0.5]), np.eye(4) * 0.01, 0.25)
    pois = [Poi(0, [1, 2, 3], 0.5, 0.07, gaussian=g), Poi(1, [0, 0, 1], 1.5, 0.01)]
    p = write_pois(tmp_path / "out" / "pois.json", pois, "gmm-as", {"poi_threshold": 2.5}, "world", "x.traj")
    doc = json.loads(p.read_text())
    assert doc["algorithm"] == "gmm-as" and doc["frame"] == "world" and doc["source"] == "x.traj"
    assert doc["pois"][0]["radius"] == 0.2 and doc["pois"][1]["gaussian"] is None
    assert len(doc["pois"][0]["gaussian"]["covariance"]) == 4
    back = read_pois(p)
    assert [q.id for q in back] == [0, 1]
    np.testing.assert_allclose(back[0].position, [1, 2, 3])
    np.testing.assert_allclose(back[0].gaussian.covariance, np.eye(4) * 0.01)
    assert back[1].gaussian is None and back[0].time == 0.5


@pytest.mark.parametrize("content, expect", [
    (None, "no such POI file"),
    ("{not json", "not valid JSON"),
    ('{"x": 1}', 'no "pois" key'),
    ('{"pois": [{"position": [1, 2]}]}', "pois[0].position"),
    ('{"pois": [{"position": [1, "a", 3]}]}', "pois[0].position"),
    ('{"pois": [{"position": [1, 2, 3], "radius": -1}]}', "pois[0].radius"),
])
def test_read_pois_errors(tmp_path, content, expect):
    p = tmp_path / "pois.json"
    if content is not None:
        p.write_text(content)
    with pytest.raises(PoiFileError) as exc:
        read_pois(p)
    assert isinstance(exc.value, KinfuError)
    assert expect in str(exc.value) and str(p) in str(exc.value)


def test_read_pois_document_keeps_metadata(tmp_path):
    p = write_pois(tmp_path / "pois.json", [], "zvc", {"zvc_threshold": 1.72})
    doc = read_pois_document(p)
    assert doc["pois"] == [] and doc["parameters"]["zvc_threshold"] == 1.72
