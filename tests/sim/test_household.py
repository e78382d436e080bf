"""Household (YCB-like) composite objects: parts share one ground-truth label, keep their own colours, and the
exact SDF agrees with the rendered mesh."""

from __future__ import annotations

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.household import KINDS, household_object, household_scene, object_kind
from kinfu_cli.sim.scene import COMPOSITE, scene_label_cloud


def test_household_scene_labels_are_per_object_and_parts_share_them():
    scene = household_scene(2)
    assert 5 <= len(scene.objects) <= 11
    pts, lab = scene_label_cloud(scene, spacing=0.006)
    assert set(np.unique(lab)) == {0} | {scene.label_of(o.id) for o in scene.objects}
    drill = scene.object("drill")
    mine = pts[lab == scene.label_of("drill")]
    c, s = np.cos(drill.yaw), np.sin(drill.yaw)
    q = mine - np.asarray(drill.center)
    local = np.stack([c * q[:, 0] + s * q[:, 1], -s * q[:, 0] + c * q[:, 1], q[:, 2]], axis=-1)
    on_part = np.stack([np.abs(p.sdf(local)) < 1e-3 for p in drill.parts])
    assert on_part.any(axis=0).all()  # every labelled point lies on one of the drill's parts
    assert (on_part.sum(axis=1) > 20).all()  # and every part (battery, handle, barrel, chuck) is seen labelled


def test_parts_keep_their_colours_under_one_label():
    scene = household_scene(2)
    target = scene.raycasting_scene()
    for oid, n_colours in (("drill", 2), ("mustard", 2), ("cracker_box", 3)):
        g = target.labels == scene.label_of(oid)
        assert g.sum() == len(scene.object(oid).parts)
        assert len(np.unique(target.albedo[g].round(3), axis=0)) == n_colours


@pytest.mark.parametrize("kind", KINDS)
def test_sdf_and_mesh_agree(kind):
    o = household_object(kind, kind, xy=(0.1, -0.2), base_z=0.7, yaw=0.8)
    v = np.asarray(o.mesh.vertices)
    d = o.sdf(v)
    assert d.max() < 1e-6  # no mesh vertex outside the exact shape
    assert np.mean(np.abs(d) < 1e-4) > 0.5  # most of them on its surface (others hidden inside another part)
    lo, hi = v.min(axis=0), v.max(axis=0)  # it rests on the surface, as tall as its size says
    assert abs(lo[2] - 0.7) < 1e-9 and abs(hi[2] - lo[2] - o.size[2]) < 1e-9
    if o.shape == COMPOSITE:
        assert o.to_json()["parts"] and object_kind(f"{kind}_2") == kind


def test_household_scene_is_seeded_and_checks_counts():
    a, b = household_scene(7), household_scene(7)
    assert a.to_json() == b.to_json()
    assert len(household_scene(7, n_objects=11).objects) == 11
    with pytest.raises(ConfigError):
        household_scene(0, n_objects=12)
