"""Grasp poses from superquadrics (thesis ch. 7.2, 7.4, 8.2): constraints on generated objects, cones, the
lifting rule, multi-part obstacles, non-convergence reporting and `kinfu grasp` end to end."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.grasp.constraints import Cone, GraspConstraints, Workspace, check_cones, default_workspaces, \
    preset_cone
from kinfu_cli.grasp.evaluate import PLANE, check_grasp, composite_objects, generated_objects
from kinfu_cli.grasp.hand import HandModel
from kinfu_cli.grasp.plan import GraspOptions, grasp_object, plan_grasps
from kinfu_cli.grasp.solve import CONSTRAINT_TOL, grasp_part
from kinfu_cli.segmentation.superquadric import Superquadric, rpy_to_matrix

UP = PLANE[:3]


def _grasp(parts, cones=()):
    ws = default_workspaces(np.array([q.center for q in parts]), UP)
    opts = GraspOptions(hand="right", cones=list(cones))
    return grasp_object(1, parts, PLANE, ws, opts), opts, ws


def _heights(g):
    pts = g.position + np.vstack([g.hand.l_points(), g.hand.v_points()]) @ g.rotation.T
    return pts @ PLANE[:3] + PLANE[3]


def test_hand_points_lie_on_the_palm_half_of_h():
    h = HandModel()
    L = h.l_points()
    assert len(L) == 48 and np.all(L[:, 2] <= h.size[2] + 1e-12)  # palm side of H's centre
    F = np.sum(((L - h.h_center()) / np.asarray(h.size)) ** 2, axis=1)
    assert np.allclose(F, 1.0)
    assert np.allclose(L[0], 0.0)  # the palm pole
    assert h.lifted(np.array([0.02, 0.03, 0.1])).size[1] == pytest.approx(0.1)


def test_constraints_hold_and_h_overlaps_generated_objects():
    """Table 7.2 sizes x box / cylinder / ellipsoid: every grasp converges, every constraint holds when
    rechecked from the pose, no hand point below the table, and H's palm half lies within 15 mm RMS of
    the object surface (median < 8 mm)."""
    objs = [o for o in generated_objects(yaws=1, seed=3) if len(o[1]) == 1][::2]
    overlaps = []
    for name, parts in objs:
        o, opts, ws = _grasp(parts)
        chk = check_grasp(o, PLANE, opts, ws)
        assert chk["converged"] and chk["satisfied"], name
        assert _heights(o.best).min() >= -CONSTRAINT_TOL, name
        assert o.best.position @ UP > 0.0
        overlaps.append(chk["overlap_rms_m"])
    assert max(overlaps) < 0.015 and np.median(overlaps) < 0.008


def test_top_cone_gives_an_approach_within_the_cone():
    sq = Superquadric(np.array([0.04, 0.03, 0.03]), np.array([0.1, 0.1]), np.array([0.4, 0.0, 0.03]),
                      rpy_to_matrix([0, 0, 0.7]))
    cone = preset_cone("top", UP, 25.0)
    o, _, _ = _grasp([sq], [cone])
    assert o.best is not None
    approach = o.best.rotation[:, 2]
    assert np.degrees(np.arccos(approach @ -UP)) <= 25.0 + 0.1
    free, _, _ = _grasp([sq])
    assert free.best is not None


def test_box_on_its_side_or_upright_changes_the_grasp():
    """The lifting rule lays H's long axis (across the palm) along the box's long axis: vertical for the
    upright box, horizontal for the same box lying on its side, and the palm is lower for the lying box."""
    half = np.array([0.025, 0.035, 0.09])
    upright = Superquadric(half, np.array([0.1, 0.1]), np.array([0.4, 0.0, half[2]]), np.eye(3))
    lying = Superquadric(half, np.array([0.1, 0.1]), np.array([0.4, 0.0, half[1]]), rpy_to_matrix([np.pi / 2, 0, 0]))
    gu, _, _ = _grasp([upright])
    gl, _, _ = _grasp([lying])
    assert gu.best is not None and gl.best is not None
    assert abs(gu.best.rotation[:, 1] @ UP) > 0.8
    assert abs(gl.best.rotation[:, 1] @ UP) < 0.5
    assert gl.best.position[2] < gu.best.position[2] - 0.02


@pytest.mark.parametrize("cone", [None, "top", "side"])
def test_multi_part_grasp_keeps_palm_and_fingers_outside_the_other_part(cone):
    """Eq. 8.2 per hand point: every one of the V palm and finger points is outside every other part, under
    each cone preset (with the constraint on their sum, 2 of 15 points ended inside under the top preset)."""
    cones = [] if cone is None else [preset_cone(cone, UP)]
    for seed in (1, 2):
        for name, parts in composite_objects(np.random.default_rng(seed)):
            o, opts, ws = _grasp(parts, cones)
            chk = check_grasp(o, PLANE, opts, ws)
            assert chk["satisfied"], (name, cone)
            assert chk["obstacle_constraint_min"] >= -CONSTRAINT_TOL
            assert chk["hand_points_inside_obstacles"] == 0 and chk["obstacle_penetration_m"] == 0.0
            assert len(o.candidates) == 2  # one per target part


def test_infeasible_cones_and_workspace_are_refused():
    with pytest.raises(ConfigError, match="infeasible orientation cones"):
        check_cones([Cone("z", (0, 0, -1), 10), Cone("x", (0, 0, -1), 10)])
    doc = {"segments": [{"id": 1, "kind": "object", "superquadric": {"params": [0.03, 0.03, 0.05, 0.1, 0.1, 0.4, 0,
                                                                                0.05, 0, 0, 0]}}],
           "support_plane": [0, 0, 1, 0]}
    ws = {"right": Workspace((0, -1, -1), (1, 1, -0.1))}
    with pytest.raises(ConfigError, match="below the support plane") as e:
        plan_grasps(doc, GraspOptions(hand="right", workspaces=ws))
    assert e.value.parameter == "workspace_right"


def test_non_convergence_is_reported_without_a_pose():
    """An optimiser stopped after one iteration has not converged: the JSON says so and gives no pose."""
    doc = {"segments": [{"id": 3, "kind": "object", "superquadric": {"params": [0.03, 0.03, 0.05, 0.1, 0.1, 0.4, 0,
                                                                                0.05, 0, 0, 0]}}],
           "support_plane": [0, 0, 1, 0]}
    res = plan_grasps(doc, GraspOptions(hand="both", max_iter=1, n_starts=1))
    g = res.to_json()["grasps"][0]
    assert g["converged"] is False and g["pose"] is None and g["pre_grasp"] is None
    assert "constraint" in g["reason"]
    assert any("segment 3" in w for w in res.warnings)


def _box_scene_segments(tmp_path):
    """segments.json of a box on a table, from `kinfu segment`'s library path on a sampled surface."""
    from kinfu_cli.segmentation.pipeline import analyse_cloud

    s = 0.008
    tx, ty = np.meshgrid(np.arange(-0.2, 0.2, s), np.arange(-0.2, 0.2, s))
    table = np.stack([tx.ravel(), ty.ravel(), np.zeros(tx.size)], 1)
    c, h = np.array([0.05, 0.0, 0.05]), np.array([0.03, 0.04, 0.05])
    table = table[~((np.abs(table[:, 0] - c[0]) <= h[0]) & (np.abs(table[:, 1] - c[1]) <= h[1]))]
    pts, nrm = [table], [np.tile([0.0, 0.0, 1.0], (len(table), 1))]
    for ax in range(3):
        o = [i for i in range(3) if i != ax]
        U, V = np.meshgrid(np.arange(-h[o[0]], h[o[0]] + 1e-9, s), np.arange(-h[o[1]], h[o[1]] + 1e-9, s))
        for sign in (-1, 1):
            if ax == 2 and sign < 0:
                continue  # the bottom face is on the table
            p = np.zeros((U.size, 3))
            p[:, o[0]], p[:, o[1]], p[:, ax] = U.ravel(), V.ravel(), sign * h[ax]
            n = np.zeros_like(p)
            n[:, ax] = sign
            pts.append(p + c)
            nrm.append(n)
    doc = analyse_cloud(np.vstack(pts), np.vstack(nrm)).to_json()
    path = tmp_path / "segments.json"
    path.write_text(json.dumps(doc, default=float))
    return path, c, h


@pytest.mark.slow
def test_cli_grasps_a_segmented_box_scene(tmp_path):
    seg, c, h = _box_scene_segments(tmp_path)
    out = tmp_path / "grasps.json"
    r = CliRunner().invoke(cli, ["grasp", str(seg), "-o", str(out), "--plot", str(tmp_path / "g.png"), "--quiet"])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert (tmp_path / "g.png").stat().st_size > 10000
    g = doc["grasps"][0]
    assert g["converged"] and g["hand"] in ("right", "left")
    T = np.array(g["pose"]["matrix"])
    assert np.allclose(T[:3, 3], g["pose"]["position"])
    assert np.linalg.norm(T[:3, 3] - c) < 0.12  # at the box
    pre = np.array(g["pre_grasp"]["position"])
    assert np.linalg.norm(T[:3, 3] - 0.05 * T[:3, 2] - pre) < 1e-9
    q = np.array(g["pose"]["quaternion_xyzw"])
    assert abs(np.linalg.norm(q) - 1) < 1e-9
    assert g["overlap_rms_m"] < 0.015 and isinstance(g["active_constraints"], list)
    # rerun refuses to overwrite nothing of kinfu's; bad input: infeasible cones -> one line, exit 2
    bad = CliRunner().invoke(cli, ["grasp", str(seg), "-o", str(tmp_path / "b.json"), "--cone", "z:0,0,-1:10",
                                   "--cone", "x:0,0,-1:10"])
    assert bad.exit_code == 2
    lines = [ln for ln in bad.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: error:") and "--cone" in lines[0]
    assert not (tmp_path / "b.json").exists()
    # --cone-aperture sets the presets' aperture: without --cone top / side it would be ignored
    bad = CliRunner().invoke(cli, ["grasp", str(seg), "-o", str(tmp_path / "c.json"), "--cone-aperture", "20"])
    lines = [ln for ln in bad.output.splitlines() if ln.strip()]
    assert bad.exit_code == 2 and len(lines) == 1 and lines[0].startswith("kinfu: error: --cone-aperture")
    assert not (tmp_path / "c.json").exists()


def test_an_empty_item_in_a_cone_direction_is_named():
    """'z:0,,1:30' said "expected 'top', 'side' or 'AXIS:dx,dy,dz:deg'": the comma-list options' words now."""
    from kinfu_cli.core.errors import ConfigError
    from kinfu_cli.grasp.constraints import parse_cone

    with pytest.raises(ConfigError, match="an empty item in the cone's direction") as err:
        parse_cone("z:0,,1:30", np.array([0.0, 0.0, 1.0]))
    assert err.value.parameter == "cones"
    assert parse_cone("z:0,0,-1:30", np.array([0.0, 0.0, 1.0])).direction == (0.0, 0.0, -1.0)


def test_bad_segments_file_is_one_line_error(tmp_path):
    bad = tmp_path / "segments.json"
    bad.write_text("{not json")
    for args, word in (([str(bad)], "not a JSON file"), ([str(tmp_path / "none.json")], "no such file"),
                       ([str(bad), "--hand-size", "0.03,0.05"], "--hand-size")):
        if word == "--hand-size":
            bad.write_text(json.dumps({"segments": []}))
        r = CliRunner().invoke(cli, ["grasp", *args, "-o", str(tmp_path / "g.json")])
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("kinfu: error:"), r.output
        assert word in lines[0]
    bad.write_text(json.dumps({"segments": [{"id": 1, "kind": "object", "superquadric": None}]}))
    r = CliRunner().invoke(cli, ["grasp", str(bad), "-o", str(tmp_path / "g.json")])
    assert r.exit_code == 2 and "no object segment has a superquadric" in r.output
    assert not (tmp_path / "g.json").exists()


@pytest.mark.slow
def test_eval_grasp_satisfies_every_constraint_on_generated_objects(tmp_path):
    out = tmp_path / "e.json"
    r = CliRunner().invoke(cli, ["eval", "grasp", "--conditions", "none", "--yaws", "1", "--scenes", "", "-o", str(out),
                                 "--quiet"])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    single = doc["generated"]["summary"]["none/single"]
    assert single["objects"] == 18 and single["converged_share"] == 1.0 and single["satisfied_share"] == 1.0
    assert single["plane_penetration_max_m"] <= CONSTRAINT_TOL and single["overlap_rms_median_m"] < 0.008
    multi = doc["generated"]["summary"]["none/multi"]
    assert multi["satisfied_share"] == 1.0


def test_segments_json_multi_superquadric_parts_are_grasped_with_obstacles():
    """segments.json of `kinfu segment --multi-sq` holds the parts' parameters: each becomes a target once,
    per hand, with the other part as obstacle."""
    name, parts = composite_objects(np.random.default_rng(2))[0]
    doc = {"segments": [{"id": 7, "kind": "object", "superquadric": parts[0].to_json(),
                         "multi_superquadric": {"parts": [q.to_json() for q in parts], "planes": []}}],
           "support_plane": [0, 0, 2, 0]}
    res = plan_grasps(doc, GraspOptions(hand="both"))
    g = res.to_json()["grasps"][0]
    assert g["parts"] == 2 and len(g["candidates"]) == 4 and g["converged"]
    assert g["target_part"] in (0, 1) and "obstacle:0" in g["constraints"]
    assert g["constraints"]["obstacle:0"] >= -CONSTRAINT_TOL


def test_analytic_gradients_match_central_differences():
    """`_Problem.value_and_grad` (cost of eq. 7.4 and every constraint) equals central differences of
    `evaluate` on box-like, round and two-part objects, with and without cones, at random poses."""
    from kinfu_cli.grasp import solve
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    objs = generated_objects(1, 0)
    worst = 0.0
    for _, parts in objs[::9] + objs[-2:]:
        for cones in ([], [preset_cone("top", UP)], [preset_cone("side", UP)]):
            prob = solve._Problem(parts[0], parts[1:], HandModel(), GraspConstraints(PLANE, None, cones))
            prob.R0 = Rotation.random(random_state=int(rng.integers(1 << 30))).as_matrix()
            x = np.concatenate([parts[0].center + rng.normal(scale=0.05, size=3), rng.normal(scale=0.8, size=3)])
            c, g, v, J = prob.value_and_grad(x)
            E = 1e-6 * np.eye(6)
            cc, gg = prob.evaluate(np.vstack([x, x + E, x - E]))
            assert c == pytest.approx(cc[0], rel=1e-12) and np.allclose(v, gg[0], rtol=1e-12, atol=1e-15)
            gfd, Jfd = (cc[1:7] - cc[7:]) / 2e-6, (gg[1:7] - gg[7:]).T / 2e-6
            worst = max(worst, np.abs(g - gfd).max() / np.abs(gfd).max(), np.abs(J - Jfd).max() / np.abs(Jfd).max())
    assert worst < 1e-6, worst


def test_top_cone_grasps_stop_at_the_optimum():
    """Under the top cone, SLSQP used to reach the optimum and run on to its iteration limit (135-236
    iterations, up to 0.7 s, on 4 of these 36 objects): forward differences left the active cone ~1e-6
    violated, above SLSQP's stopping tolerance. Now every grasp converges well inside the limit."""
    top = [preset_cone("top", UP)]
    its = []
    for _, parts in generated_objects(2, 0):
        if len(parts) > 1:
            continue
        o, opts, ws = _grasp(parts, top)
        assert o.best is not None and check_grasp(o, PLANE, opts, ws)["satisfied"]
        its.append(o.best.iterations)
    assert len(its) == 36 and max(its) <= 80, sorted(its)[-4:]
