"""Synthetic tabletop scenes: seeded, objects resting on the table without overlap, changes."""

import numpy as np
import open3d as o3d
import pytest

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.sim.scene import (LABEL_NONE, LABEL_TABLE, Table, box_scene, make_tabletop_scene,
                                 primitive_tabletop_scene, resting_object)


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


def test_exact_signed_distance_matches_the_meshes():
    """Scene.sdf is the analytic distance of the same shapes the meshes tessellate: it agrees with open3d's
    distance to the meshes up to the tessellation, and is negative inside."""
    table = Table()
    shapes = [("box", {"x": 0.12, "y": 0.08, "z": 0.1}), ("cylinder", {"radius": 0.04, "height": 0.12}),
              ("sphere", {"radius": 0.05}), ("torus", {"torus_radius": 0.05, "tube_radius": 0.02}),
              ("cone", {"radius": 0.05, "height": 0.12})]
    rng = np.random.default_rng(0)
    for shape, params in shapes:
        obj = resting_object("o", shape, params, xy=(0.1, -0.05), base_z=table.top_z, yaw=0.7)
        pts = np.asarray(obj.center) + rng.uniform(-0.12, 0.12, (4000, 3))
        rc = o3d.t.geometry.RaycastingScene()
        rc.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(obj.mesh))
        mesh_d = rc.compute_signed_distance(o3d.core.Tensor(pts.astype(np.float32))).numpy()
        d = obj.sdf(pts)
        assert np.abs(np.abs(d) - np.abs(mesh_d)).max() < 2e-3, shape  # tessellation of the round shapes
        assert np.mean(np.sign(d) == np.sign(mesh_d)) > 0.99, shape
        v = np.asarray(obj.mesh.vertices)
        assert np.abs(v[:, 2].min() - table.top_z) < 1e-9, shape  # resting on the surface
    scene = make_tabletop_scene(1, n_objects=5, floor=False)
    rc = scene.raycasting_scene().scene
    pts = rng.uniform([-0.7, -0.5, 0.0], [0.7, 0.5, 1.0], (20000, 3))
    exact = np.abs(scene.sdf(pts))
    assert np.abs(exact - rc.compute_distance(o3d.core.Tensor(pts.astype(np.float32))).numpy()).max() < 2e-3


def test_nearest_labels_name_the_part_a_surface_point_lies_on():
    scene = primitive_tabletop_scene(0)
    assert not scene.floor and len(scene.objects) == 6
    stacked = scene.objects[-1]
    base = next(o for o in scene.objects if o.shape == "box")
    assert stacked.shape == "box" and np.allclose(stacked.center[:2], base.center[:2])
    assert np.isclose(stacked.center[2] - stacked.size[2] / 2, base.center[2] + base.size[2] / 2)  # on the base
    visible = [o for o in scene.objects if o is not base]  # the base's top is under the stacked box
    tops = np.array([[o.center[0], o.center[1], o.center[2] + o.size[2] / 2] for o in visible])
    assert scene.nearest_labels(tops, 0.005).tolist() == [scene.label_of(o.id) for o in visible]
    assert scene.nearest_labels(np.array([[0.55, 0.35, 0.7], [0.0, 0.0, 1.5]]), 0.01).tolist() == [LABEL_TABLE,
                                                                                                   LABEL_NONE]


def test_box_scene_is_three_boxes_on_a_slab_at_z0():
    scene = box_scene()
    v = np.asarray(scene.mesh().vertices)
    assert v[:, 2].min() == pytest.approx(-0.02) and v[:, 2].max() == pytest.approx(0.25)
    assert [o.size[2] for o in scene.objects] == [0.15, 0.25, 0.08]
    assert scene.sdf(np.array([[0.0, 0.0, 0.2]]))[0] == pytest.approx(0.05)  # 5 cm above the first box
