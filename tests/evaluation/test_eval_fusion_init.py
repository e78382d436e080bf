"""`kinfu eval fusion` on a volume that continued another (fuse --init) with nothing forgotten says the earlier
frames blend in.

Before: the sample tabletop's scan (--end 5.5) continued with the after-change frames (--start 5.5 --init, no
--clear-pois) scored against the after state gave Table 1 errors of 0.023 m with `warnings: []` (the state check
saw only the 12 after-change frames); with --clear-pois the paper's flow gives 0.008 m.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from kinfu_cli.evaluation.reconstruction import init_warnings
from kinfu_cli.sim.scenario import GroundTruth

T0 = 1767225600_000000000


def _truth() -> GroundTruth:
    stamps = T0 + np.arange(5, dtype=np.int64) * 1_000_000_000
    info = {"t0_ns": T0, "frames": {"scan": 3},
            "changes": [{"position": [0.3, 0.1, 0.76], "kind": "pick", "object": "obj4"}]}
    return GroundTruth(Path("gt"), info, np.eye(3), 32, 24, stamps, np.tile(np.eye(4), (5, 1, 1)))


def _report(init: Path | None, cleared=()) -> dict:
    """A `kinfu fuse` report.json's parts that say how the volume was started."""
    grid = {"sizing": {"mode": "init" if init else "auto"}, "frames_in_volume": 5,
            "placement": f"--init {init}" if init else "centred on the first 3 frame(s)"}
    return {"grid": grid, "frames": {"used": 2, "start_s": 2.5, "end_s": None}, "cleared_spheres": list(cleared)}


def test_an_init_volume_with_nothing_forgotten_is_a_warning(tmp_path):
    scan = tmp_path / "scan"
    scan.mkdir()
    (scan / "report.json").write_text(json.dumps({"frames": {"start_s": None, "end_s": 2.5}}))
    (w,) = init_warnings(_report(scan / "volume.npz"), _truth())
    assert str(scan / "volume.npz") in w and "(3 of its 5 frames)" in w and "from the start to 2.5 s" in w
    assert "obj4" in w and "blended" in w


def test_forgotten_spheres_or_no_init_is_no_warning(tmp_path):
    sphere = {"center": [0.3, 0.1, 0.76], "radius": 0.1, "source": "pois.json#0"}
    assert init_warnings(_report(tmp_path / "v.npz", [sphere]), _truth()) == []
    assert init_warnings(_report(None), _truth()) == []
    assert init_warnings(None, _truth()) == [] and init_warnings({"grid": 3}, _truth()) == []
