"""Per-voxel ground-truth labels (sim.voxel_labels): kinfu synth's ground_truth/labels.npz for tabletop and room."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from kinfu_cli.evaluation.segment_eval import PredictedSegments, evaluate_segments, load_ground_truth_labels
from kinfu_cli.io.labelled_cloud import read_labelled_cloud
from kinfu_cli.sim.room import ROOM_OBJECTS, make_room, write_room_ground_truth
from kinfu_cli.sim.scenario import LABELS_VOXEL, make_scenario, write_scene_voxel_labels
from kinfu_cli.sim.scene import scene_label_cloud


@pytest.fixture(scope="module")
def objects_labels(tmp_path_factory):
    sc = make_scenario(0, width=64, height=48, frames=2, layout="objects")
    path = write_scene_voxel_labels(tmp_path_factory.mktemp("vl") / "labels.npz", sc.scene_after)
    return sc.scene_after, path


def test_voxel_labels_agree_with_the_scene_geometry(objects_labels):
    """Every stored voxel is occupied (centre inside a part or within half a voxel of its surface, at most 3
    voxels deep) by the part of its label; every present object has voxels; the file reads as a labels file."""
    scene, path = objects_labels
    with np.load(path) as z:
        idx, pts, lab, origin, vs = z["index"], z["points"], z["labels"], z["origin"], float(z["voxel_size"])
    assert vs == LABELS_VOXEL and np.allclose(origin / vs, np.round(origin / vs))
    assert np.allclose(pts, origin + (idx + 0.5) * vs)
    assert set(np.unique(lab)) == {0} | {scene.label_of(o.id) for o in scene.present_objects}
    for o in scene.present_objects:
        mine = lab == scene.label_of(o.id)
        d = o.sdf(pts[mine])
        assert d.max() <= vs / 2 + 1e-9 and d.min() >= -3 * vs - 1e-9, o.id
    assert len(read_labelled_cloud(path).points) == len(pts)


def test_voxel_labels_match_the_labelled_surface_points(objects_labels):
    """labels.ply's surface points take the same label from the nearest labelled voxel (>= 97 %), the touching
    twins included, and kinfu eval segment scores labels.ply against labels.npz as a perfect segmentation."""
    scene, path = objects_labels
    pts, lab = scene_label_cloud(scene)
    vox = read_labelled_cloud(path)
    _, j = cKDTree(vox.points).query(pts)
    assert np.mean(vox.labels[j] == lab) >= 0.97
    for twin in ("twin_a", "twin_b"):
        mine = lab == scene.label_of(twin)
        assert np.mean(vox.labels[j[mine]] == lab[mine]) >= 0.95, twin
    doc = evaluate_segments(PredictedSegments(pts, lab, None, "label property"), vox, max_distance=0.015).document
    assert doc["object_recall"] == 1.0 and doc["boundary_recall"] >= 0.9 and doc["boundary_precision"] >= 0.9


def test_room_ground_truth_has_labels(tmp_path):
    """The room scene gets labels.ply: background 0 (floor, walls) and table, sofa, shelf, named in changes.json;
    the table's points lie in its box, standing on the floor up to its 0.75 m top, none inside another part."""
    room = make_room(0, width=32, height=24, frames=3)
    gt = write_room_ground_truth(room, tmp_path / "gt", {})
    cloud = load_ground_truth_labels(gt)
    assert set(np.unique(cloud.labels)) == {0, 1, 2, 3}
    import json
    names = json.loads((gt / "changes.json").read_text())["labels"]
    assert [names[str(k + 1)] for k in range(3)] == list(ROOM_OBJECTS)
    table = cloud.points[cloud.labels == 1] @ room.W[:3, :3]  # back to the z-up room frame
    assert table[:, 2].min() < 0.05 and 0.74 < table[:, 2].max() < 0.78
    assert np.ptp(table[:, 0]) < 1.05 and np.ptp(table[:, 1]) < 0.75
    assert np.min([d for _, d in room.part_distances(cloud.points)], axis=0).min() >= -1e-3
