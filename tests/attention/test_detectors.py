"""GMM-AS and ZVC: synthetic actions recovered, the paper's threshold rule, EM properties, `kinfu poi`."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.attention.detect import detector_params, make_detector
from kinfu_cli.attention.em import fit_em, fit_em_numpy
from kinfu_cli.attention.gmm_as import GmmActivitySaliency
from kinfu_cli.attention.zvc import ZeroVelocityCrossing
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError, TrajectoryError
from kinfu_cli.evaluation.poi import resample_speed
from kinfu_cli.io.polhemus import write_polhemus
from kinfu_cli.io.trajectory import Trajectory
from kinfu_cli.sim.hand import random_task, synth_hand_trajectory

TASKS = [(kind, seed) for kind in ("placement", "removal", "pick-and-place") for seed in (0, 1, 2)]


def _dists(pois, changes):
    P = np.array([p.position for p in pois]).reshape(-1, 3)
    G = np.array([c.position for c in changes]).reshape(-1, 3)
    if len(P) == 0:
        return np.full(len(G), np.inf), np.zeros(0)
    d = np.linalg.norm(P[:, None] - G[None], axis=2)
    return d.min(axis=0), d.min(axis=1)


@pytest.mark.parametrize("kind, seed", TASKS)
@pytest.mark.parametrize("noise", [0.0, 0.005])
def test_gmm_as_recovers_every_synthetic_action_within_5cm(kind, seed, noise):
    traj, changes = synth_hand_trajectory(random_task(kind, seed=seed), seed=seed, noise_std=noise)
    det = GmmActivitySaliency().fit(traj)
    to_gt, to_poi = _dists(det.pois_, changes)
    assert np.all(to_gt < 0.05), f"{kind}/{seed}: actions missed, nearest POI {to_gt}"
    assert np.all(to_poi < 0.20), f"{kind}/{seed}: false positives at {to_poi}"
    assert len(det.gaussians_) == det.n_components_ == len(det.saliency_)
    times = [g.mean[3] for g in det.gaussians_]
    assert times == sorted(times)
    # each POI carries its Gaussian, in seconds on the trajectory's clock, near the pause
    for p, c in zip(sorted(det.pois_, key=lambda p: p.time), sorted(changes, key=lambda c: c.time)):
        assert c.t_start - 0.5 <= p.time <= c.t_end + 0.5
        assert p.gaussian is not None and p.gaussian.covariance.shape == (4, 4)


@pytest.mark.parametrize("kind, seed", TASKS)
def test_zvc_recovers_every_clean_synthetic_action_within_5cm(kind, seed):
    traj, changes = synth_hand_trajectory(random_task(kind, seed=seed), seed=seed)
    det = ZeroVelocityCrossing().fit(traj)
    to_gt, _ = _dists(det.pois_, changes)
    assert np.all(to_gt < 0.05), f"{kind}/{seed}: actions missed, nearest POI {to_gt}"
    assert all(p.gaussian is None for p in det.pois_)


def test_gmm_as_is_invariant_to_speed_multipliers():
    traj, changes = synth_hand_trajectory(random_task("pick-and-place", seed=4), seed=4)
    ref = np.array([p.position for p in GmmActivitySaliency().fit(traj).pois_])
    for speed in (0.25, 4.0):
        got = np.array([p.position for p in GmmActivitySaliency().fit(resample_speed(traj, speed)).pois_])
        assert got.shape == ref.shape
        assert np.abs(got - ref).max() < 0.01


def test_threshold_rule_reproduces_paper_tables_5_and_6():
    det = GmmActivitySaliency(poi_threshold=1.5, neighbours=2, threshold_mode="available")
    t5 = np.array([0.005880, 0.001646, 0.001352, 0.073616, 0.001749, 0.002383])
    th5 = det._thresholds(t5)
    np.testing.assert_allclose(th5[1:-1], [0.040424, 0.031084, 0.002673, 0.038675], atol=2e-6)
    assert list(np.flatnonzero(t5[1:-1] > th5[1:-1]) + 1) == [3]  # only Gaussian 4 (1-based)
    t6 = np.array([0.002341, 0.025118, 0.001191, 0.001855, 0.066844, 0.000679, 0.003140])
    th6 = det._thresholds(t6)
    np.testing.assert_allclose(th6[1:-1], [0.002693, 0.036059, 0.035187, 0.002574, 0.035919], atol=2e-6)
    assert list(np.flatnonzero(t6[1:-1] > th6[1:-1]) + 1) == [1, 4]  # Gaussians 2 and 5
    assert np.isnan(th6[0]) and np.isnan(th6[-1])
    # the literal Alg. 3 rule divides by 2 Lambda even at the borders
    lit = GmmActivitySaliency(poi_threshold=1.0, threshold_mode="literal")._thresholds(t5)
    assert lit[1] == pytest.approx((t5[0] + t5[2] + t5[3]) / 4)


def test_numba_em_matches_numpy_reference_and_bic_prefers_true_k():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, 300)
    centres = np.array([[0, 0, 0], [0.5, 0, 0], [0.5, 0.5, 0]])
    pos = centres[np.minimum((t * 3).astype(int), 2)] + rng.normal(0, 0.02, (300, 3))
    x = np.c_[pos, t]
    reg = np.array([1e-6] * 3 + [1e-4])
    a, b = fit_em(x, 3, reg), fit_em_numpy(x, 3, reg)
    assert a.log_likelihood == pytest.approx(b.log_likelihood, rel=1e-3)
    np.testing.assert_allclose(np.sort(a.means[:, 0]), np.sort(b.means[:, 0]), atol=1e-3)
    bics = [fit_em(x, k, reg).bic(len(x)) for k in (1, 2, 3)]
    assert bics[2] < bics[1] < bics[0]


def test_em_is_equivariant_to_the_time_unit():
    """The claim behind `time_scale`: scaling t (and its floor) leaves the mixture unchanged."""
    traj, _ = synth_hand_trajectory(random_task("placement", seed=1), seed=1)
    x = np.c_[traj.positions, traj.t - traj.t[0]]
    reg = np.array([1e-4] * 3 + [1e-4])
    a = fit_em(x, 4, reg)
    x2 = x.copy()
    x2[:, 3] *= 100.0
    b = fit_em(x2, 4, reg * np.array([1, 1, 1, 1e4]))
    np.testing.assert_allclose(a.means[:, :3], b.means[:, :3], atol=1e-6)
    np.testing.assert_allclose(a.weights, b.weights, atol=1e-6)
    assert b.log_likelihood == pytest.approx(a.log_likelihood - len(x) * np.log(100.0), rel=1e-6)


def test_noise_estimate_tracks_added_noise():
    traj, _ = synth_hand_trajectory(random_task("placement", seed=2), seed=2)
    rng = np.random.default_rng(1)
    for std in (0.01, 0.03):
        est = GmmActivitySaliency.estimate_noise(traj.positions + rng.normal(0, std, traj.positions.shape))
        assert est == pytest.approx(std, rel=0.2)


def test_detectors_reject_bad_input():
    with pytest.raises(TrajectoryError, match="1 samples"):
        GmmActivitySaliency().fit(Trajectory(t=[0.0], positions=[[0, 0, 0]], source="one.traj"))
    bad = Trajectory(t=np.arange(5) / 100, positions=np.r_[np.zeros((4, 3)), [[np.nan, 0, 0]]], source="nan.traj")
    with pytest.raises(TrajectoryError, match="nan.traj: sample 4 is not finite"):
        ZeroVelocityCrossing().fit(bad)
    traj = Trajectory(t=np.arange(50) / 100, positions=np.zeros((50, 3)))
    with pytest.raises(ConfigError, match="^saliency: expected one of"):
        GmmActivitySaliency(saliency="bogus").fit(traj)
    with pytest.raises(ConfigError, match="^zvc_r1/zvc_r2: expected 0 < r1 < r2"):
        ZeroVelocityCrossing(r1=0.3, r2=0.1).fit(traj)


def test_detector_params_split_one_flat_set_between_the_detectors():
    params = detector_params(poi_threshold=2.0, zvc_r1=0.05, zvc_threshold=1.6, radius=0.3)
    assert params == {"gmm-as": {"poi_threshold": 2.0, "radius": 0.3},
                      "zvc": {"r1": 0.05, "threshold": 1.6, "radius": 0.3}}
    literal = detector_params(poi_threshold=2.0, zvc_threshold=1.6, literal=True)
    assert literal["gmm-as"] == GmmActivitySaliency.LITERAL and literal["zvc"] == {"threshold": 1.72, "rule": "ratio"}
    gmm, zvc = make_detector("gmm-as", params["gmm-as"]), make_detector("zvc", params["zvc"])
    assert gmm.get_params()["radius"] == zvc.radius == 0.3 and zvc.r1 == 0.05
    assert make_detector("gmm-as").get_params() == GmmActivitySaliency().get_params()
    with pytest.raises(ConfigError, match="^algorithm: "):
        make_detector("kmeans")


def test_short_still_trajectory_gives_no_pois_not_an_error():
    traj = Trajectory(t=np.arange(12) / 100, positions=np.zeros((12, 3)) + 1e-4 * np.arange(12)[:, None])
    assert GmmActivitySaliency().fit(traj).pois_ == []


# --- kinfu poi --------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def pnp_traj(tmp_path_factory):
    traj, changes = synth_hand_trajectory(random_task("pick-and-place", seed=5), seed=5)
    p = tmp_path_factory.mktemp("poi") / "task.traj"
    write_polhemus(p, traj)
    return p, changes


def test_cli_poi_writes_the_pois_json_contract(pnp_traj, tmp_path):
    src, changes = pnp_traj
    out = tmp_path / "o" / "pois.json"
    png = tmp_path / "o" / "pois.png"
    res = CliRunner().invoke(cli, ["poi", str(src), "-o", str(out), "--plot", str(png)])
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert set(doc) >= {"pois", "algorithm", "parameters", "frame", "source"}
    assert doc["algorithm"] == "gmm-as" and doc["parameters"]["poi_threshold"] == 1.5
    assert len(doc["pois"]) == 2
    for p in doc["pois"]:
        assert set(p) >= {"id", "position", "time", "saliency", "radius", "gaussian"}
        assert p["radius"] == 0.2 and len(p["gaussian"]["covariance"]) == 4 and len(p["gaussian"]["mean"]) == 4
    gt = np.array([c.position for c in changes])
    pos = np.array([p["position"] for p in doc["pois"]])
    assert np.linalg.norm(pos[:, None] - gt[None], axis=2).min(axis=0).max() < 0.05
    assert png.stat().st_size > 10_000


def test_cli_poi_zvc_json_stdout(pnp_traj, tmp_path):
    src, _ = pnp_traj
    res = CliRunner().invoke(cli, ["poi", str(src), "--algorithm", "zvc", "--json", "-o", str(tmp_path / "z.json"),
                                   "--plot", str(tmp_path / "z.png")])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["algorithm"] == "zvc" and all(p["gaussian"] is None for p in doc["pois"])
    assert doc["parameters"]["rule"] == "relative" and doc["parameters"]["relative"] == 0.28
    assert doc["parameters"]["half_width"] == 4


@pytest.mark.parametrize("args, expect", [
    (["missing.traj"], "no such trajectory file"),
    (["EMPTY"], "empty trajectory file"),
    (["GOOD", "--time-scale", "fast"], "--time-scale"),
    (["GOOD", "--zvc-r1", "0.5", "--algorithm", "zvc"], "--zvc-r1/--zvc-r2"),
])
def test_cli_poi_errors_are_one_line_and_leave_no_output(pnp_traj, tmp_path, args, expect):
    src, _ = pnp_traj
    empty = tmp_path / "empty.traj"
    empty.write_text("")
    args = [str(src) if a == "GOOD" else str(empty) if a == "EMPTY" else str(tmp_path / a) if a.endswith(".traj")
            else a for a in args]
    out = tmp_path / "pois.json"
    res = CliRunner().invoke(cli, ["poi", *args, "-o", str(out)])
    assert res.exit_code == 2
    assert expect in res.output and "Traceback" not in res.output
    assert res.output.strip().count("\n") == 0
    assert not out.exists()


def test_cli_poi_on_the_sample_recording(sample_dir, tmp_path):
    out = tmp_path / "pois.json"
    res = CliRunner().invoke(cli, ["poi", str(sample_dir / "recording.mcap"), "-o", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    doc = json.loads((sample_dir / "ground_truth" / "changes.json").read_text())
    hand = np.array([c.get("hand_position", c["position"]) for c in doc["changes"]])
    pos = np.array([p["position"] for p in json.loads(out.read_text())["pois"]]).reshape(-1, 3)
    assert len(pos) >= len(hand)
    assert np.linalg.norm(pos[:, None] - hand[None], axis=2).min(axis=0).max() < 0.05
    # absolute stamps of the POIs fall inside the pauses of the changes (within 0.3 s)
    stamps = sorted(p["stamp_ns"] for p in json.loads(out.read_text())["pois"])
    for c in doc["changes"]:
        assert min(abs(s - c["stamp_ns"]) for s in stamps) < 0.3e9


def test_cli_poi_literal_reading_is_selectable(pnp_traj, tmp_path):
    src, _ = pnp_traj
    out = tmp_path / "lit.json"
    res = CliRunner().invoke(cli, ["poi", str(src), "--literal", "-o", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    params = json.loads(out.read_text())["parameters"]
    assert params["saliency"] == "literal" and params["poi_threshold"] == 2.5 and params["resample"] == 0
    assert params["threshold_mode"] == "literal" and params["time_scale"] == 1.0
    res = CliRunner().invoke(cli, ["poi", str(src), "--literal", "--algorithm", "zvc", "-o", str(out), "--quiet"])
    assert res.exit_code == 0 and json.loads(out.read_text())["parameters"]["threshold"] == 1.72


def test_tracking_gap_is_not_taken_for_dwell():
    """A 3 s dropout during a transport must not become a POI (gaps are shortened before the fit)."""
    traj, changes = synth_hand_trajectory(random_task("placement", seed=3), seed=3)
    ref = GmmActivitySaliency().fit(traj)
    # remove the samples of the first transport (0.2-0.6 of the way to the pause) and shift the rest by 3 s
    t0, t1 = traj.t[0], changes[0].t_start
    a, b = t0 + 0.2 * (t1 - t0), t0 + 0.6 * (t1 - t0)
    keep = (traj.t < a) | (traj.t > b)
    t = traj.t[keep] + np.where(traj.t[keep] > b, 3.0, 0.0)
    gap = Trajectory(t=t, positions=traj.positions[keep])
    det = GmmActivitySaliency().fit(gap)
    to_gt, to_poi = _dists(det.pois_, changes)
    assert len(det.pois_) == len(ref.pois_) == 1
    assert to_gt.max() < 0.05 and to_poi.max() < 0.05
    # POI times on the trajectory's clock (after the gap: shifted by the 3 s)
    for p in det.pois_:
        assert changes[0].t_start + 3.0 - 0.5 <= p.time <= changes[0].t_end + 3.0 + 0.5


def test_zvc_rule_follows_the_threshold_and_checks_its_parameters():
    assert ZeroVelocityCrossing().rule_ == "relative"
    assert ZeroVelocityCrossing(threshold=1.72).get_params()["rule"] == "ratio"  # the paper's absolute rule
    assert ZeroVelocityCrossing(rule="ratio").threshold_ == 1.5
    assert ZeroVelocityCrossing(rule="relative", threshold=1.72).rule_ == "relative"
    traj, _ = synth_hand_trajectory(random_task("placement", seed=0), seed=0)
    with pytest.raises(ConfigError, match="^zvc_rule: expected one of relative, ratio"):
        ZeroVelocityCrossing(rule="fast").fit(traj)
    with pytest.raises(ConfigError, match="^zvc_relative"):
        ZeroVelocityCrossing(relative=1.5).fit(traj)


def test_zvc_relative_rule_is_blind_to_the_person_speed_and_keeps_quick_grasps():
    """The relative rule compares the local speed with the task's own: the same path performed faster
    gives the same slow samples, and pauses played 4x shorter are still found (the ratio rule at the
    paper's ZVCTh loses them)."""
    from kinfu_cli.evaluation.poi_loo import quicken_pauses

    for seed in range(3):
        traj, changes = synth_hand_trajectory(random_task("pick-and-place", seed=seed), seed=seed)
        ref = np.array([p.position for p in ZeroVelocityCrossing().fit(traj).pois_])
        fast = np.array([p.position for p in ZeroVelocityCrossing().fit(resample_speed(traj, 2.0)).pois_])
        assert fast.shape == ref.shape and np.abs(fast - ref).max() < 0.03
        quick = quicken_pauses(traj, factor=3.0)
        assert quick.duration < traj.duration
        to_gt, _ = _dists(ZeroVelocityCrossing().fit(quick).pois_, changes)
        assert np.all(to_gt < 0.05), f"seed {seed}: quick grasps missed, nearest POI {to_gt}"


def test_zvc_slow_limit_is_what_the_mask_compares_with():
    traj, _ = synth_hand_trajectory(random_task("removal", seed=1), seed=1)
    for det in (ZeroVelocityCrossing().fit(traj), ZeroVelocityCrossing(threshold=1.5).fit(traj)):
        np.testing.assert_array_equal(det.slow_, det.speed_r1_ < det.slow_limit_)
    rel = ZeroVelocityCrossing().fit(traj)
    assert np.ptp(rel.slow_limit_) == 0.0  # one limit per task: relative x the task's 95th percentile speed


def test_cli_zvc_threshold_selects_the_ratio_rule_and_bad_relative_names_its_flag(pnp_traj, tmp_path):
    src, _ = pnp_traj
    out = tmp_path / "z.json"
    res = CliRunner().invoke(cli, ["poi", str(src), "--algorithm", "zvc", "--zvc-threshold", "1.72", "-o", str(out),
                                   "--quiet"])
    assert res.exit_code == 0, res.output
    params = json.loads(out.read_text())["parameters"]
    assert params["rule"] == "ratio" and params["threshold"] == 1.72
    res = CliRunner().invoke(cli, ["poi", str(src), "--algorithm", "zvc", "--zvc-relative", "2", "-o",
                                   str(tmp_path / "y.json"), "--quiet"])
    assert res.exit_code == 2 and "--zvc-relative" in res.output and "Traceback" not in res.output


def test_a_long_pause_split_over_two_gaussians_is_one_poi():
    """The synthetic pause fills 45 % of the task: under the 0.03 x duration time floor it takes two
    consecutive Gaussians; merge_distance makes them one POI at the change (0 keeps both, the paper)."""
    traj, changes = synth_hand_trajectory(random_task("placement", seed=3), seed=3)
    split = GmmActivitySaliency(merge_distance=0.0).fit(traj)
    merged = GmmActivitySaliency().fit(traj)
    assert len(split.pois_) == 2 and len(merged.pois_) == 1
    assert merged.pois_[0].extra["merged_components"] == [p.extra["component"] for p in split.pois_]
    to_gt, _ = _dists(merged.pois_, changes)
    assert to_gt.max() < 0.01
    assert changes[0].t_start <= merged.pois_[0].time <= changes[0].t_end


def test_resample_to_fewer_samples_than_a_few_gaussians_need_is_refused():
    # resample 1 ran as raw samples and 2-5 fitted nothing (0 POIs), both without a word
    from kinfu_cli.attention.gmm_as import RESAMPLE_GAUSSIANS, GmmActivitySaliency

    for bad in (1, 2, 5, RESAMPLE_GAUSSIANS * 8 - 1):
        with pytest.raises(ConfigError, match="at least 32 samples") as err:
            GmmActivitySaliency(resample=bad).check_params()
        assert err.value.parameter == "resample"
    GmmActivitySaliency(resample=0).check_params()
    GmmActivitySaliency(resample=32).check_params()
