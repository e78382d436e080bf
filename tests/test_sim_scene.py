"""Synthetic tabletop scenes: seeded, objects resting on the table without overlap, changes."""

import numpy as np
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.scene import Table, make_tabletop_scene


def test_same_seed_same_scene_other_seed_other_scene():
    a, b, c = make_tabletop_scene(3), make_tabletop_scene(3), make_tabletop_scene(4)
    assert [o.to_json() for o in a.objects] == [o.to_json() for o in b.objects]
    assert np.array_equal(np.asarray(a.mesh().vertices), np.asarray(b.mesh().vertices))
    assert [o.center for o in a.objects] != [o.center for o in c.objects]


@pytest.mark.parametrize("seed", [0, 1, 2, 7])
def test_objects_rest_on_the_table_without_overlap(seed):
    scene = make_tabletop_scene(seed, n_objects=5)
    table = scene.table
    shapes = {o.shape for o in scene.objects}
    assert {"box", "cylinder", "sphere"} <= shapes and shapes & {"torus", "cone"}
    for o in scene.objects:
        v = np.asarray(o.mesh.vertices)
        assert abs(v[:, 2].min() - table.top_z) < 1e-6, o.id          # resting on the top
        assert table.contains_xy(v[:, :2], margin=0.05).all(), o.id    # on the table, away from its edges
        assert np.allclose((v.min(0) + v.max(0)) / 2, o.center, atol=2e-3)
    for i, a in enumerate(scene.objects):
        for b in scene.objects[i + 1:]:
            d = np.linalg.norm(np.subtract(a.center[:2], b.center[:2]))
            assert d >= a.footprint_radius + b.footprint_radius, (a.id, b.id)


def test_changes_place_remove_move():
    scene = make_tabletop_scene(0, n_objects=3)
    rng = np.random.default_rng(0)
    gone = scene.with_change("removal", "obj2")
    assert [o.present for o in gone.objects] == [True, False, True]
    assert len(gone.mesh().triangles) < len(scene.mesh().triangles)
    back = gone.with_change("placement", "obj2", position=(0.1, -0.2))
    assert back.object("obj2").present and back.object("obj2").center[:2] == (0.1, -0.2)
    xy = scene.free_spot(rng, scene.object("obj1").footprint_radius, avoid=scene.object("obj1").center[:2],
                         min_dist=0.2)
    moved = scene.with_change("move", "obj1", position=xy)
    assert moved.object("obj1").center[:2] == xy
    assert moved.object("obj1").center[2] == scene.object("obj1").center[2]
    assert scene.object("obj1").center != moved.object("obj1").center   # the original is unchanged
    with pytest.raises(ConfigError, match="not on the table"):
        gone.with_change("removal", "obj2")
    with pytest.raises(ConfigError, match="no object 'nope'"):
        scene.with_change("removal", "nope")
    with pytest.raises(ConfigError, match="unknown scene change"):
        scene.with_change("teleport", "obj1")


def test_too_many_objects_is_a_config_error():
    with pytest.raises(ConfigError, match="no free spot|does not fit"):
        make_tabletop_scene(0, n_objects=12, table=Table(size=(0.4, 0.3)))
