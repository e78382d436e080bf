"""The object-driven planner on a volume whose voxels were all seen fewer than W_th times says that is why.

Before: `kinfu nbv --mode objects` on a 3-frame volume (`kinfu synth --frames 3`, or a short window) said "no
candidate views: the volume has no contour point (observed surface next to unknown space)" although the volume
holds plenty of observed surface next to unknown space: none of it was observed the W_th = 5 times the planner
needs to call it known.
"""

from kinfu_cli.core.camera import CameraModel
from kinfu_cli.nbv.workflow import rank_object_views
from tests.nbv.test_objects import _box_volume

CAM = CameraModel(fx=40.0, fy=40.0, cx=31.5, cy=23.5, width=64, height=48, min_range=0.3)


def test_too_few_observations_are_named_as_the_reason(tmp_path):
    _box_volume(4).save(tmp_path / "volume.npz")
    views = rank_object_views(tmp_path / "volume.npz", CAM)
    assert views.plan.candidates_total == 0
    assert "no occupied voxel was observed the W_th = 5 times" in views.empty_reason
    assert views.warnings[0] == views.empty_reason
