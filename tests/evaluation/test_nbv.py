"""`kinfu eval nbv`: the closed attention loop on the bundled sample scene (small and coarse)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation.nbv_loop import LoopConfig, run_loop

SMALL = dict(voxel_size=0.02, width=160, height=120, scan_every=2,
             sphere=dict(lon_step=60, lat_step=30, roll_step=90))


@pytest.fixture(scope="module")
def loop_doc(sample_dir):
    cfg = LoopConfig(strategies=("poi", "random"), views=2, **SMALL)
    return run_loop(sample_dir / "ground_truth", cfg)


def test_unknown_voxels_in_poi_spheres_decrease_and_poi_views_beat_random(loop_doc):
    doc = loop_doc
    assert len(doc["pois"]) >= 1
    # GMM-AS finds the pick and the place, at the hand (about 0.1 m above the object's centre)
    assert all(p["distance_to_nearest_change"] < 0.2 for p in doc["pois"])
    for r in doc["strategies"].values():
        for series in r["unknown"].values():
            assert all(b <= a for a, b in zip(series, series[1:])), series
        assert r["final_unknown"] < 0.05 * r["initial_unknown"]
    poi, rnd = doc["strategies"]["poi"], doc["strategies"]["random"]
    first = str(doc["pois"][0]["id"])
    # from the same cleared volume, the best-ranked first view reveals more of S(POI) than a random one
    assert poi["unknown"][first][0] == rnd["unknown"][first][0] > 1000
    assert poi["unknown"][first][1] < rnd["unknown"][first][1]
    assert poi["views_until_incth"][first] is not None and poi["views_until_incth"][first] <= 2
    err = poi["error"]
    assert err["accuracy_mean_m"] < 0.01 and err["completeness"] > 0.5
    assert set(doc["time_s"]) >= {"initial_scan", "rank", "render", "integrate", "total"}


def test_cli_eval_nbv_writes_table_json_and_plot(sample_dir, tmp_path):
    out, png = tmp_path / "loop.json", tmp_path / "loop.png"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(sample_dir), "--strategy", "fixed", "--views", "1",
                                   "--voxel-size", "0.025", "--width", "80", "--height", "60", "--scan-every", "4",
                                   "--lon-step", "90", "--lat-step", "45", "--roll-step", "180", "--no-noise",
                                   "-o", str(out), "--plot", str(png)])
    assert res.exit_code == 0, res.output
    assert "unknown voxels in each POI sphere" in res.output and "fixed" in res.output
    doc = json.loads(out.read_text())
    series = list(doc["strategies"]["fixed"]["unknown"].values())
    assert all(len(s) == 2 and s[1] < s[0] for s in series)
    assert png.stat().st_size > 5000


@pytest.mark.parametrize("args, expect", [
    (["--strategy", "best"], "--strategy"),
    (["--views", "0"], "--views"),
])
def test_cli_eval_nbv_bad_options(sample_dir, args, expect):
    res = CliRunner().invoke(cli, ["eval", "nbv", str(sample_dir), "--quiet"] + args)
    assert res.exit_code == 2 and "kinfu: error:" in res.output and expect in res.output


def test_cli_eval_nbv_missing_scene(tmp_path):
    res = CliRunner().invoke(cli, ["eval", "nbv", str(tmp_path / "nope"), "--quiet"])
    assert res.exit_code == 2 and "no such scene" in res.output
    (tmp_path / "empty").mkdir()
    res = CliRunner().invoke(cli, ["eval", "nbv", str(tmp_path / "empty"), "--quiet"])
    assert res.exit_code == 2 and "changes.json" in res.output


def test_cli_eval_nbv_on_a_bare_mesh_needs_a_poi(sample_dir, tmp_path):
    mesh = sample_dir / "ground_truth" / "scene_after.ply"
    small = ["--views", "1", "--voxel-size", "0.03", "--width", "80", "--height", "60", "--lon-step", "90",
             "--lat-step", "45", "--roll-step", "180", "--no-noise", "--quiet", "--strategy", "poi"]
    res = CliRunner().invoke(cli, ["eval", "nbv", str(mesh)] + small)
    assert res.exit_code == 2 and "--poi" in res.output
    out = tmp_path / "m.json"
    res = CliRunner().invoke(cli, ["eval", "nbv", str(mesh), "--poi", "0.36", "-0.15", "0.80", "-o", str(out)] + small)
    assert res.exit_code == 0, res.output
    series = json.loads(out.read_text())["strategies"]["poi"]["unknown"]["0"]
    assert len(series) == 2 and series[1] < 0.5 * series[0]
