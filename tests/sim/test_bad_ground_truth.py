"""load_ground_truth checks what the evaluations read from changes.json and camera_poses.txt: a K of zeros, a
billion-pixel image, a NaN change or pose, 'objects' that is not a list of objects are a RecordingError naming
the file (they were numpy warnings with NaN scores, out-of-memory, or an AttributeError traceback)."""

from __future__ import annotations

import json

import pytest

from kinfu_cli.core.errors import RecordingError
from kinfu_cli.sim.scenario import load_ground_truth

K = [30.0, 0, 9.5, 0, 30.0, 7.5, 0, 0, 1]
POSE = "0.0 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n"


def _gt(tmp_path, poses=POSE, **change):
    doc = {"camera": {"K": K, "width": 20, "height": 16}, "changes": [{"position": [0, 0, 0]}], "objects": []}
    for key, value in change.items():
        if key in ("K", "width"):
            doc["camera"][key] = value
        else:
            doc[key] = value
    (tmp_path / "changes.json").write_text(json.dumps(doc))
    (tmp_path / "camera_poses.txt").write_text(poses)
    return tmp_path


def test_a_good_folder_reads(tmp_path):
    gt = load_ground_truth(_gt(tmp_path))
    assert gt.width == 20 and gt.poses.shape == (1, 4, 4)
    frames = {"count": 36, "scan": None, "after": 12, "rate_hz": 5.0}  # null: a scene without a change
    assert load_ground_truth(_gt(tmp_path, frames=frames, t0_ns=10**18, hand={"start_time": 6.1},
                                 table={"plane": [0, 0, 1, -0.7]})).info["frames"] == frames


@pytest.mark.parametrize("change, needle", [
    ({"K": [0.0] * 9}, "focal"),
    ({"K": [float("nan")] * 9}, "focal"),
    ({"width": 0}, "image size"),
    ({"width": 10 ** 9}, "image size"),
    ({"changes": [{"position": [float("nan"), 0, 0]}]}, "change position"),
    ({"objects": "abc"}, "'objects'"),
    ({"table": {"center": "middle"}}, "table"),
    ({"poses": "0.0 nan 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n"}, "not finite"),
    # the numbers the evaluations read without a default (2026-11-29: ValueError tracebacks, a numpy warning, an
    # object reported as not reconstructed)
    ({"frames": {"count": 36, "scan": "x"}}, "frames scan is 'x'"),
    ({"frames": {"rate_hz": -5.0}}, "frames rate_hz"),
    ({"t0_ns": "t"}, "t0_ns is 't'"),
    ({"t0_ns": float("nan")}, "t0_ns is nan"),
    ({"hand": {"start_time": "s"}}, "hand start_time is 's'"),
    ({"table": {"plane": [0, 0, 0, 0]}}, "table plane"),
    ({"objects": [{"id": "obj1", "center": [float("nan"), 0, 0]}]}, "object 'obj1' center"),
    ({"objects": [{"id": "obj1"}, {"id": "obj2"}, {"id": "obj1"}]}, 'object ids repeat ("obj1")'),
])
def test_a_damaged_ground_truth_is_a_recording_error(tmp_path, change, needle):
    poses = change.pop("poses", POSE)
    with pytest.raises(RecordingError) as err:
        load_ground_truth(_gt(tmp_path, poses, **change))
    assert needle in str(err.value) and str(tmp_path) in str(err.value)
