"""A declared up that the data contradict is kept but pointed out, as a REP-103 frame's z is.

Before: the rgbd-tabletop-box imported with `--up 0,1,0` (y-up given for its y-down camera frame) fused with
up [0, 1, 0] from the recording and no warning, although the table plane below the cameras points along
[-0.01, -0.91, -0.42], 155 deg away.
"""

import numpy as np

from kinfu_cli.fusion.up import choose_up
from kinfu_cli.io.world_up import WorldUp
from tests.fusion.test_up import _floor_scene


def test_a_declared_up_against_the_floor_is_a_warning_and_is_kept():
    pts, nrm, poses = _floor_scene((0, -1, 0))
    kw = dict(points=pts, normals=nrm, camera_poses=poses, up_name="--up")
    c = choose_up(world="world", world_from_tf=True, declared=WorldUp("world", np.array([0.0, 1, 0])), **kw)
    assert c.source == "recording" and np.allclose(c.up, [0, 1, 0])
    (w,) = c.warnings
    assert "declares up [0.0, 1.0, 0.0]" in w and "180 deg away" in w and "--up" in w
    assert c.evidence["estimate"]["source"] == "estimated-plane"


def test_a_declared_up_the_floor_agrees_with_is_silent():
    pts, nrm, poses = _floor_scene((0, -1, 0))
    c = choose_up(world="world", world_from_tf=True, declared=WorldUp("world", np.array([0.0, -1, 0])),
                  points=pts, normals=nrm, camera_poses=poses)
    assert c.source == "recording" and c.warnings == []
