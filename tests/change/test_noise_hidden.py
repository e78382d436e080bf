"""`kinfu diff` says what the depth-noise margin may hide: clusters as large as a region it dropped (how many,
how far from the cameras), and a volume whose camera is evidently not the Kinect v1 the noise model is for.

Before: a 5 cm box taken off a wall 3.2 m from the cameras was dropped as depth noise with only a count
(counts.within_depth_noise) and warnings []; a RealSense volume got the Kinect v1 model with no word.
"""

from __future__ import annotations

import json

import numpy as np

from kinfu_cli.change.diff import ChangeParams, diff_grids, diff_volumes
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.io.tum import write_tum

VS = 0.01
CAMERA = np.array([0.2, 0.2, 0.0])  # looking along +z
FAR_CUBE = (10, 15, 10, 15, 315, 320)  # a 5 cm box on the wall, 3.2 m from the camera (a region by size)


def _labels(with_cube: bool) -> np.ndarray:
    """Free space up to a wall at 3.2 m (unknown behind it), and optionally the box against it (the wall behind
    it unseen)."""
    lab = np.zeros((30, 30, 330), dtype=np.int8)  # 1 occupied, 0 unknown, -1 empty
    lab[:, :, :320] = -1
    lab[:, :, 320:323] = 1
    if with_cube:
        x0, x1, y0, y1, z0, z1 = FAR_CUBE
        lab[x0:x1, y0:y1, z0:z1] = 1
        lab[x0:x1, y0:y1, z1:] = 0
    return lab


def _grids(intrinsics=None):
    return [TernaryGrid(_labels(c), np.zeros(3), VS, "world", intrinsics=intrinsics) for c in (True, False)]


def test_a_far_cube_dropped_as_depth_noise_is_a_warning():
    before, after = _grids({"fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5, "width": 640, "height": 480})
    assert len(diff_grids(before, after, ChangeParams(noise_sigmas=0)).regions) == 1  # a region without the noise
    r = diff_grids(before, after, cameras=(np.array([CAMERA]), None))
    doc = r.to_json()
    assert r.regions == [] and doc["counts"]["within_depth_noise"]["removed"] > 0
    assert doc["counts"]["within_depth_noise_regions"] == {"removed": 1, "added": 0}
    (w,) = r.warnings
    assert "1 cluster(s)" in w and "1 removed" in w and "3.2 m from the cameras" in w, w
    assert doc["parameters"]["depth_noise"]["model"].startswith("kinect-v1")
    assert doc["parameters"]["depth_noise"]["sensors"]["before"]["kinect_like"] is True


def test_a_realsense_volume_is_named_in_a_warning(tmp_path):
    paths = []
    for name, grid in zip(("before", "after"), _grids({"fx": 425.0, "fy": 425.0, "cx": 424.0, "cy": 240.0,
                                                       "width": 848, "height": 480})):
        folder = tmp_path / name
        folder.mkdir()
        save_ternary(folder / "ternary.npz", grid)
        write_tum(folder / "trajectory.tum", np.array([0]), np.array([np.eye(4)]) + np.pad(
            CAMERA[:, None], ((0, 1), (3, 0))))
        paths.append(folder / "ternary.npz")
    (tmp_path / "after" / "report.json").write_text(json.dumps({"frames": {"depth_units_m": 0.001}}))
    r = diff_volumes(*paths)
    sensors = r.to_json()["parameters"]["depth_noise"]["sensors"]
    assert sensors["before"] == {"kinect_like": False, "evidence": "depth images 848x480, not the 4:3 of a Kinect v1"}
    assert sensors["after"]["kinect_like"] is False and "RealSense SDK" in sensors["after"]["evidence"]
    named = [w for w in r.warnings if "Kinect v1 model" in w]
    assert len(named) == 2 and str(paths[1]) in named[1] and "depth units 0.001 m" in named[1], r.warnings
