"""Segmentation of a fused synthetic scene (simulated Kinect frames -> TernaryVolume) vs object meshes."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation.segments import fuse_synthetic_scene, scene_gt_labels, score_segmentation
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume


@pytest.fixture(scope="module")
def fused():
    return fuse_synthetic_scene(4, resolution=256, size=1.6, frames=24)


@pytest.mark.slow
def test_fused_scene_object_recall_and_boundaries(fused):
    vol, scene = fused
    res = analyse_volume(vol, SegmentOptions())
    gt, names = scene_gt_labels(res.segmentation.points, scene)
    score = score_segmentation(res.segmentation.points, res.segmentation.labels, gt, t_eval=0.02, ignore_gt=-1)
    assert score.objects_total == len(scene.present_objects)
    assert score.object_recall >= 0.9, score.per_object
    assert score.boundary_precision >= 0.7 and score.boundary_recall >= 0.7, score
    # every object segment got a superquadric that fits it to within a few millimetres
    for o in score.per_object:
        fit = res.superquadrics[o["segment"]]
        assert not isinstance(fit, str) and fit.residual < 0.006, (names[o["object"]], fit)


@pytest.mark.slow
def test_cli_segment_on_a_fusion_volume_with_plots(fused, tmp_path):
    vol, scene = fused
    vol.save(tmp_path / "volume.npz")
    out = tmp_path / "seg"
    res = CliRunner().invoke(cli, ["segment", str(tmp_path / "volume.npz"), "-o", str(out), "--plot"])
    assert res.exit_code == 0, res.output
    assert "segments + support plane" in res.output
    doc = json.loads((out / "segments.json").read_text())
    objs = [s for s in doc["segments"] if s["kind"] == "object"]
    assert len(objs) >= len(scene.present_objects)
    plane = next(s for s in doc["segments"] if s["kind"] == "support_plane")
    assert abs(-plane["plane"][3] - scene.table.top_z) < 0.01
    for name in ("segments.ply", "saliency.ply", "segments.png", "saliency.png"):
        assert (out / name).stat().st_size > 1000
