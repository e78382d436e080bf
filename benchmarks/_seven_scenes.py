"""The shared 7-Scenes kitchen frames for the benchmarks, read with the importer's own folder reader
(`kinfu_cli.io.rgbd_folders`): intrinsics, poses and depth exactly as `kinfu import` sees them."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from kinfu_cli.io.rgbd_folders import read_depth_mm, scan_folder  # noqa: E402

SEVEN = REPO.parent / "shared" / "data" / "rgbd-7scenes-redkitchen"


def seven_scenes_frames(n: int, color: bool = True) -> list[tuple]:
    """The first n frames as (depth m float32, colour RGB uint8 or None, K, T_world_camera); 65535 (no reading)
    and 0 become 0."""
    folder = scan_folder(SEVEN)
    out = []
    for f in folder.frames[:n]:
        mm = read_depth_mm(f, folder.depth_units_per_m)
        d = np.where(mm < 65535, mm.astype(np.float32) / 1000.0, 0).astype(np.float32)
        c = cv2.cvtColor(cv2.imread(str(f.color_path)), cv2.COLOR_BGR2RGB) if color and f.color_path else None
        out.append((d, c, folder.K, f.T_world_camera))
    return out
