"""The segmentation ground-truth scene (`synth --scene objects`) and the labelled surface points of scenes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.labelled_cloud import read_labelled_cloud
from kinfu_cli.sim.scenario import make_scenario
from kinfu_cli.sim.scene import (LABEL_FLOOR, LABEL_TABLE, make_tabletop_scene, movable_objects, scene_label_cloud,
                                 segmentation_scene)


@pytest.mark.parametrize("scene", [segmentation_scene(0), make_scenario(1, width=32, height=24, frames=2,
                                                                         layout="household").scene_after],
                         ids=["objects0", "household1"])
def test_part_distances_near_are_exact_wherever_a_part_is_near(scene):
    # scene_label_cloud's distances are evaluated only near each part's mesh box: exact there, and where a part
    # is left out (+inf) it is farther than the reach asked for (the household scene has a floor)
    pts, _ = scene_label_cloud(scene, spacing=0.012)
    pts = pts + np.random.default_rng(0).normal(scale=0.01, size=pts.shape)
    near, full = dict(scene._part_distances_near(pts, reach=0.005)), dict(scene._part_distances(pts))
    assert near.keys() == full.keys()
    for label, d in near.items():
        kept = np.isfinite(d)
        assert np.array_equal(d[kept], full[label][kept]) and np.all(full[label][~kept] > 0.005), label
        assert 0 < kept.sum() < len(pts), label  # each part is near some points and not all


@pytest.mark.parametrize("scene", [segmentation_scene(0), segmentation_scene(5), make_tabletop_scene(2)],
                         ids=["objects0", "objects5", "tabletop2"])
def test_label_cloud_agrees_with_the_exact_geometry(scene):
    pts, lab = scene_label_cloud(scene, spacing=0.006)
    near = scene.nearest_labels(pts)
    expect = np.where(np.isin(near, (LABEL_FLOOR, LABEL_TABLE)), 0, near)
    assert np.mean(expect == lab) > 0.999
    # every labelled point lies on the surface it is labelled with (mesh vs exact shape: < 1.5 mm)
    dist = dict(scene._part_distances(pts))
    for o in scene.present_objects:
        mine = lab == scene.label_of(o.id)
        assert mine.sum() > 100, o.id
        assert np.abs(dist[scene.label_of(o.id)][mine]).max() < 1.5e-3, o.id
    # nothing labelled is hidden inside another part
    assert np.min([d for d in dist.values()], axis=0).min() > -1e-3


def test_objects_scene_holds_the_hard_cases():
    s = segmentation_scene(3)
    ids = [o.id for o in s.objects]
    assert set(ids) == {"stack_base", "stack_top", "twin_a", "twin_b", "mug", "textured_box", "textured_can", "ball"}
    base, top = s.object("stack_base"), s.object("stack_top")
    assert top.center[2] - top.size[2] / 2 == pytest.approx(base.center[2] + base.size[2] / 2)
    a, b = s.object("twin_a"), s.object("twin_b")
    pts, lab = scene_label_cloud(s, spacing=0.004)
    bpts = pts[lab == s.label_of("twin_b")]
    gap = a.sdf(bpts)
    assert gap.min() > -1e-6 and gap.min() < 0.006  # touching (the shared face is hidden), never overlapping
    assert np.abs(np.subtract(a.colour, b.colour)).max() < 0.05  # nearly the same colour
    mug = s.object("mug")
    local = pts[lab == s.label_of("mug")] - np.asarray(mug.center)
    c, sn = np.cos(mug.yaw), np.sin(mug.yaw)
    x_local = c * local[:, 0] + sn * local[:, 1]
    assert (x_local > mug.params["radius"] + 0.01).sum() > 50  # the handle is there and seen
    assert {o.texture for o in s.objects} == {"", "stripes"}
    target = s.raycasting_scene()
    assert sorted(set(target.textured.tolist())) == [0, 1, 2]
    assert {o.id for o in movable_objects(s)} >= {"ball"} and not {"stack_base", "stack_top", "twin_a",
                                                                   "twin_b"} & {o.id for o in movable_objects(s)}


def test_mug_mesh_matches_its_signed_distance():
    mug = segmentation_scene(1).object("mug")
    v = np.asarray(mug.mesh.vertices)
    d = mug.sdf(v)
    assert np.abs(d[d > -1e-3]).max() < 1.5e-3  # vertices of the hidden handle half are inside the body


@pytest.mark.parametrize("kind", ["pick-and-place", "remove"])
def test_objects_scenario_changes_only_free_standing_objects(kind):
    sc = make_scenario(2, kind, width=32, height=24, frames=3, layout="objects")
    moved = {c["object"] for c in sc.changes}
    assert moved and moved <= {"mug", "textured_box", "textured_can", "ball"}


def test_synth_writes_labels_that_match_changes_json(tmp_path):
    for scene in ("objects", "tabletop", "household"):
        out = tmp_path / scene
        res = CliRunner().invoke(cli, ["synth", "-o", str(out), "--scene", scene, "--formats", "mcap", "--width", "32",
                                       "--height", "24", "--frames", "3", "-q"])
        assert res.exit_code == 0, res.output
        gt = json.loads((out / "ground_truth" / "changes.json").read_text())
        cloud = read_labelled_cloud(out / "ground_truth" / "labels.ply")
        present = {o["label"] for o in gt["objects"] if o["present_after"]}
        assert set(np.unique(cloud.labels).tolist()) == {0} | present
        assert gt.get("layout", "tabletop") == scene
