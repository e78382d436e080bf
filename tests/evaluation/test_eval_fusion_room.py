"""`kinfu eval fusion` on a static scene without tabletop objects (the ground truth `kinfu synth --scene room`
writes: one scene.ply, no table, no objects).

Before: `kinfu eval fusion out/room --ground-truth room_yd` failed with "room_yd/ground_truth/scene_after.ply:
missing ground-truth mesh" (it looked only for the tabletop's scene_before/after.ply), and past that with "no
'table' entry (needed for the object measures)": the room that synth writes could not be scored at all.
"""

import json

import numpy as np
import open3d as o3d

from kinfu_cli.evaluation.reconstruction import evaluate_fusion

T0 = 1767225600000000000


def _room_truth(folder):
    """A 1 m box (a sofa) 3 m in front of one camera, as a room ground truth: scene.ply, no table, no objects."""
    folder.mkdir()
    box = o3d.geometry.TriangleMesh.create_box(1.0, 1.0, 1.0).translate((-0.5, -0.5, 0.0))
    box = box.subdivide_midpoint(3)
    o3d.io.write_triangle_mesh(str(folder / "scene.ply"), box)
    K = [[29.25, 0.0, 15.5], [0.0, 29.25, 11.5], [0.0, 0.0, 1.0]]
    info = {"changes": [], "objects": [], "scenario": "room", "t0_ns": T0, "up": [0.0, 0.0, 1.0],
            "camera": {"K": K, "width": 32, "height": 24}, "frames": {"count": 1}}
    (folder / "changes.json").write_text(json.dumps(info))
    T = np.array([[1, 0, 0, 0.0], [0, 0, 1, -3.0], [0, -1, 0, 0.5], [0, 0, 0, 1]])  # looks along +y at the box
    (folder / "camera_poses.txt").write_text("# stamp_s then T\n1767225600.500000000 "
                                             + " ".join(f"{v:.9f}" for v in T.reshape(-1)) + "\n")
    return box


def test_a_room_ground_truth_scores_the_surface_and_measures_no_objects(tmp_path):
    box = _room_truth(tmp_path / "ground_truth")
    shifted = o3d.geometry.TriangleMesh(box).translate((0.003, 0.003, 0.003))  # every face 3 mm off
    rec = tmp_path / "mesh.ply"
    o3d.io.write_triangle_mesh(str(rec), shifted)
    doc = evaluate_fusion(rec, tmp_path, spacing=0.02).document
    r = doc["reconstruction"]
    assert r["samples_observed"] > 100
    assert 0.002 < r["accuracy"]["median"] < 0.006 and r["precision"] > 0.95 and r["completeness"] > 0.95
    o = doc["objects"]
    assert o["objects"] == [] and o["objects_total"] == 0 and o["table_plane"]["source"].startswith("none")
