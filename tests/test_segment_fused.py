"""Segmentation of a fused synthetic scene (simulated Kinect frames -> TernaryVolume) vs object meshes."""

from __future__ import annotations

import pytest

from kinfu_cli.evaluation.segments import fuse_synthetic_scene, scene_gt_labels, score_segmentation
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume


@pytest.mark.slow
def test_fused_scene_object_recall_and_boundaries():
    vol, scene = fuse_synthetic_scene(4, resolution=256, size=1.6, frames=24)
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
