"""`kinfu eval segment`: the metrics on hand-made labelings, the labels file reader, label transfer, the
command end to end on a small generated scene and the sweep."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation.segment_eval import (PredictedSegments, evaluate_segments, load_predicted_segments,
                                               sweep_segmentation, transfer_labels)
from kinfu_cli.evaluation.segments import consistency_error, consistency_errors, score_segmentation
from kinfu_cli.io.labelled_cloud import LabelsFileError, read_labelled_cloud, write_labelled_cloud
from tests.conftest import one_line_error


def _three_strips(n: int = 4000, seed: int = 0):
    """A 30 x 30 cm sheet: table (0) for x < 0.1, object 1 for 0.1 <= x < 0.2, object 2 beyond."""
    rng = np.random.default_rng(seed)
    pts = np.c_[rng.uniform(0, 0.3, (n, 2)), np.zeros(n)]
    gt = (pts[:, 0] >= 0.1).astype(int) + (pts[:, 0] >= 0.2)
    return pts, gt


def test_perfect_labelling_scores_one_and_zero_bce():
    pts, gt = _three_strips()
    s = score_segmentation(pts, gt + 7, gt)  # the label numbers do not matter, only the partition
    assert s.boundary_precision == 1.0 and s.boundary_recall == 1.0 and s.bce == 0.0
    assert s.object_recall == 1.0 and s.objects_total == 2
    assert s.over_segmented == 0 and s.under_segmenting == 0 and s.segments == 3


def test_merging_two_objects_is_under_segmentation_and_costs_recall():
    pts, gt = _three_strips()
    merged = np.where(gt == 2, 1, gt)
    s = score_segmentation(pts, merged, gt)
    assert s.under_segmenting == 1 and s.details["under"][0]["objects"] == [1, 2]
    assert s.over_segmented == 0
    assert s.boundary_precision == 1.0 and 0.4 < s.boundary_recall < 0.65  # one of two boundaries missed
    assert s.objects_found == 1 and s.object_recall == 0.5
    # BCE: the object-1 and object-2 points each see half their merged segment as foreign
    assert s.bce == pytest.approx(np.mean(gt > 0) * 0.5, abs=0.03)


def test_splitting_one_object_is_over_segmentation_and_costs_precision():
    pts, gt = _three_strips()
    split = gt.copy()
    split[(gt == 1) & (pts[:, 1] > 0.15)] = 9
    s = score_segmentation(pts, split, gt)
    assert s.over_segmented == 1 and s.details["over"][0] == {"object": 1, "segments": [1, 9]}
    assert s.under_segmenting == 0
    assert s.boundary_recall == 1.0 and s.boundary_precision < 0.95
    assert s.object_recall == 0.5  # neither half holds 80 % of object 1
    assert 0 < s.bce < 0.25


def test_bce_is_symmetric_bounded_and_counts_dropped_points_as_singletons():
    pts, gt = _three_strips(600)
    rng = np.random.default_rng(3)
    other = rng.integers(0, 4, len(gt))
    assert consistency_error(other, gt) == pytest.approx(consistency_error(gt, other))
    assert 0 < consistency_error(other, gt) <= 1
    one = np.zeros_like(gt)
    # one segment for everything: each point's error is the share of the cloud outside its true region
    expect = np.mean([1 - np.mean(gt == g) for g in gt])
    assert consistency_error(one, gt) == pytest.approx(expect)
    dropped = gt.copy()
    dropped[:10] = -1
    e = consistency_errors(dropped, gt)
    assert np.all(e[:10] > 0.6) and np.all(e[10:] < 0.05)


def test_label_transfer_by_nearest_neighbour_within_a_distance():
    src = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    lab, dist = transfer_labels(src, np.array([4, 5]), np.array([[0.01, 0, 0], [0.98, 0, 0], [0.5, 0, 0]]), 0.05)
    assert lab.tolist() == [4, 5, -1] and np.isinf(dist[2]) and dist[0] == pytest.approx(0.01)


def test_labels_file_round_trip_and_cloudcompare_style(tmp_path):
    pts = np.random.default_rng(0).uniform(-1, 1, (50, 3))
    lab = np.arange(50) % 4 - 1
    f = write_labelled_cloud(tmp_path / "l.ply", pts, lab)
    back = read_labelled_cloud(f)
    assert np.allclose(back.points, pts, atol=1e-6) and back.labels.tolist() == lab.tolist()
    cc = tmp_path / "cc.ply"  # CloudCompare: a scalar field 'label' is exported as float scalar_label
    cc.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                  "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float scalar_label\n"
                  "end_header\n0 0 0 255 0 0 3\n1 1 1 0 255 0 0\n")
    assert read_labelled_cloud(cc).labels.tolist() == [3, 0]
    np.savez(tmp_path / "l.npz", points=pts, labels=lab)
    assert read_labelled_cloud(tmp_path / "l.npz").labels.tolist() == lab.tolist()


@pytest.mark.parametrize("content, needle", [
    (b"not a ply at all", "not a PLY file"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
     b"end_header\n0 0 0\n1 1 1\n", "no per-point 'label'"),
    (b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
     b"property float label\nend_header\n0 0 0 1.5\n1 1 1 2\n", "whole numbers"),
    (b"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
     b"property int label\nend_header\n0 0 0 1\n1 1 1 2\n", "truncated"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
     b"property int label\nend_header\n0 0 0 -4\n", ">= -1"),
])
def test_bad_labels_file_is_one_line_error(tmp_path, content, needle):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(content)
    with pytest.raises(LabelsFileError, match="bad.ply"):
        read_labelled_cloud(bad)
    good = write_labelled_cloud(tmp_path / "seg.ply", np.zeros((3, 3)), np.zeros(3))
    res = CliRunner().invoke(cli, ["eval", "segment", str(good), "--ground-truth", str(bad)])
    one_line_error(res, "bad.ply", needle)


def test_clouds_in_different_frames_are_an_error_not_a_score(tmp_path):
    pts, gt = _three_strips(500)
    seg = write_labelled_cloud(tmp_path / "seg.ply", pts + 5.0, gt)
    lab = write_labelled_cloud(tmp_path / "gt.ply", pts, gt)
    res = CliRunner().invoke(cli, ["eval", "segment", str(seg), "--ground-truth", str(lab)])
    one_line_error(res, "--max-distance", "same world frame")
    res = CliRunner().invoke(cli, ["eval", "segment", str(seg)])
    one_line_error(res, "--ground-truth")


@pytest.fixture(scope="module")
def small_scene(tmp_path_factory):
    """A coarse fusion of segmentation scene 1, segmented and written as kinfu segment does, with its labels."""
    from kinfu_cli.evaluation.segments import fuse_synthetic_scene
    from kinfu_cli.segmentation.outputs import write_segment_outputs
    from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume
    from kinfu_cli.sim.scene import scene_label_cloud

    root = tmp_path_factory.mktemp("evalseg")
    vol, scene = fuse_synthetic_scene(1, resolution=128, size=1.1, width=160, height=120, frames=12,
                                      layout="objects")
    res = analyse_volume(vol, SegmentOptions(superquadrics=False))
    write_segment_outputs(res, root / "seg")
    pts, lab = scene_label_cloud(scene, spacing=0.005)
    write_labelled_cloud(root / "labels.ply", pts, lab)
    return root, res, scene


def test_eval_segment_end_to_end(small_scene, tmp_path):
    root, res, scene = small_scene
    out = tmp_path / "ev.json"
    r = CliRunner().invoke(cli, ["eval", "segment", str(root / "seg"), "--ground-truth", str(root / "labels.ply"),
                                 "-o", str(out), "--plot", str(tmp_path / "top.png")])
    assert r.exit_code == 0, r.output
    assert "bnd P" in r.stdout and "BCE" in r.stdout
    doc = json.loads(out.read_text())
    assert doc["input"]["labels_from"] == "label property" and not doc["warnings"]
    # segments.ply's labels are the segmentation's: same scores as from memory
    mem = evaluate_segments(PredictedSegments(res.segmentation.points, res.segmentation.labels, None, "memory"),
                            read_labelled_cloud(root / "labels.ply"))
    for key in ("boundary_precision", "boundary_recall", "bce", "object_recall", "over_segmented",
                "under_segmenting"):
        assert doc[key] == pytest.approx(mem.document[key], abs=1e-6), key
    # what today's segmentation does on this scene: most objects found, boundaries mostly right
    assert doc["objects_total"] >= 6 and doc["object_recall"] >= 0.5
    assert doc["boundary_precision"] > 0.5 and doc["boundary_recall"] > 0.4 and doc["bce"] < 0.2
    assert doc["points"]["unmatched_share"] < 0.05
    assert (tmp_path / "top.png").stat().st_size > 10_000
    # segments.json names the same result: the cloud beside it is scored, with the same numbers
    via_json = load_predicted_segments(root / "seg" / "segments.json")
    assert via_json.labels.tolist() == load_predicted_segments(root / "seg").labels.tolist()
    # the ground truth scored against itself (the labels moved onto the segmented points) is perfect
    labels = read_labelled_cloud(root / "labels.ply")
    moved, _ = transfer_labels(labels.points, labels.labels, res.segmentation.points, 0.015)
    perfect = write_labelled_cloud(tmp_path / "perfect.ply", res.segmentation.points, moved)
    best = evaluate_segments(perfect, root / "labels.ply").document
    assert best["boundary_precision"] == 1.0 and best["boundary_recall"] == 1.0 and best["bce"] == 0.0
    assert best["object_recall"] == 1.0


def test_segments_json_mismatch_is_a_warning(small_scene, tmp_path):
    root, res, _ = small_scene
    import shutil

    seg = tmp_path / "seg"
    shutil.copytree(root / "seg", seg)
    # an older segments.ply (colours only, no label property): the colour groups are the segments
    import open3d as o3d

    o3d.io.write_point_cloud(str(seg / "segments.ply"), o3d.io.read_point_cloud(str(seg / "segments.ply")))
    pred = load_predicted_segments(seg)
    assert pred.source == "segment colours" and not pred.warnings
    mem = evaluate_segments(PredictedSegments(res.segmentation.points, res.segmentation.labels, None, "memory"),
                            read_labelled_cloud(root / "labels.ply")).document
    old = evaluate_segments(pred, read_labelled_cloud(root / "labels.ply")).document
    assert old["boundary_f"] == pytest.approx(mem["boundary_f"], abs=1e-6) and old["bce"] == pytest.approx(mem["bce"])
    doc = json.loads((seg / "segments.json").read_text())
    doc["segments"][0]["point_count"] += 1
    (seg / "segments.json").write_text(json.dumps(doc))
    pred = load_predicted_segments(seg)
    assert pred.warnings and "share a colour" in pred.warnings[0]


def test_mode_filter_and_mean_differ_on_photometric_scenes():
    """The sweep's volumes: one render, fused with the mean and the mode filter; with the simulator's gain /
    white-balance jitter and misregistration their surface colours differ, the geometry does not."""
    from kinfu_cli.evaluation.segments import fuse_synthetic_volumes
    from kinfu_cli.segmentation.surface import surface_from_volume

    vols, scene = fuse_synthetic_volumes(3, colors=("none", "mean", "mode"), resolution=64, size=1.1, width=96,
                                         height=72, frames=6, layout="objects", photometric=True)
    clouds = {m: surface_from_volume(v, resolution=0.02) for m, v in vols.items()}
    assert clouds["none"].colors is None and clouds["mean"].colors is not None
    assert len(clouds["mean"].points) == len(clouds["mode"].points) == len(clouds["none"].points)
    assert np.allclose(clouds["mean"].points, clouds["mode"].points)
    diff = np.linalg.norm(clouds["mean"].colors - clouds["mode"].colors, axis=1)
    assert np.mean(diff > 0.02) > 0.05  # mode picks one observed colour where the mean blends


def test_cli_sweep_over_t_ff_with_mean_and_mode(tmp_path):
    """A tiny Flood Fill sweep: one row per value for each colour volume, a stricter T_ff never gives fewer
    segments, the table and the PR curves (one mean curve per colour mode)."""
    out = tmp_path / "sweep.json"
    r = CliRunner().invoke(cli, ["eval", "segment", "--sweep", "--sweep-parameter", "t_ff", "--sweep-values",
                                 "0.15,1.0", "--scenes", "1", "--resolution", "64", "-o", str(out), "--plot",
                                 str(tmp_path / "pr.png")])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["method"] == "flood-fill" and doc["colors"] == ["mean", "mode"] and doc["photometric"]
    assert [(s["layout"], s["seed"], s["color"]) for s in doc["scenes"]] == [("objects", 1, "mean"),
                                                                            ("objects", 1, "mode")]
    for s in doc["scenes"]:
        assert [row["value"] for row in s["rows"]] == [0.15, 1.0]
        assert s["rows"][0]["segments"] >= s["rows"][1]["segments"]
        assert all(0 <= row["boundary_precision"] <= 1 and 0 <= row["bce"] <= 1 for row in s["rows"])
    assert set(doc["means"]) == {"mean", "mode"} and len(doc["means"]["mode"]["boundary_f"]) == 2
    assert "objects 1 mode" in r.stdout and "mean over scenes" in r.stdout
    assert (tmp_path / "pr.png").stat().st_size > 10_000


@pytest.mark.parametrize("args, flag", [(["--color", "mean,best"], "--color"), (["--scene", "kitchen"], "--scene"),
                                        (["--sweep-parameter", "method"], "--sweep-parameter"),
                                        (["--sweep-parameter", "t_lccp", "--sweep-values", "3"], "t_lccp"),
                                        (["--sweep-values", "nan"], "--sweep-values"),
                                        (["--sweep-values", "200"], "--sweep-values")])
def test_bad_sweep_options_are_one_line_errors(tmp_path, args, flag):
    r = CliRunner().invoke(cli, ["eval", "segment", "--sweep", "--resolution", "32", "--scenes", "0",
                                 "-o", str(tmp_path / "s.json"), *args])
    one_line_error(r, flag)
    assert "--concavity-tolerance" not in r.output  # the sweep's values, not an option the user set
    assert not (tmp_path / "s.json").exists()


@pytest.mark.slow
def test_sweep_gives_pr_points_per_value(tmp_path):
    doc = sweep_segmentation((2,), "concavity_tolerance_deg", (5.0, 40.0), colors=("none",), resolution=128,
                             size=1.1, frames=12)
    rows = doc["scenes"][0]["rows"]
    assert [r["value"] for r in rows] == [5.0, 40.0]
    # a looser convexity threshold merges more: never more segments
    assert rows[1]["segments"] <= rows[0]["segments"]
    assert all(0 <= r["boundary_precision"] <= 1 and 0 <= r["bce"] <= 1 for r in rows)
    from kinfu_cli.report.segment_eval_plot import plot_sweep_pr

    assert plot_sweep_pr(doc, tmp_path / "pr.png").stat().st_size > 10_000


def test_cli_t_lccp_sweep_in_the_thesis_rgb_distance(tmp_path):
    """--color-distance rgb sweeps T_lccp over the RGB values by default (the chroma ones would cut every box into
    faces there) and records the distance; a stricter T_lccp never gives fewer segments."""
    from kinfu_cli.evaluation.segment_eval import RGB_T_LCCP_VALUES

    out = tmp_path / "sweep.json"
    r = CliRunner().invoke(cli, ["eval", "segment", "--sweep", "--sweep-parameter", "t_lccp", "--color-distance",
                                 "rgb", "--color", "mode", "--scenes", "1", "--resolution", "64", "-o", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["color_distance"] == "rgb" and doc["values"] == list(RGB_T_LCCP_VALUES)
    segs = [row["segments"] for row in doc["scenes"][0]["rows"]]
    assert segs[0] >= segs[-1] and segs[0] > 1
    assert "colour distance: rgb" in r.stdout
