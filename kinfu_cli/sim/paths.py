"""Camera paths for synthetic frames that need no robot: poses on a circle, all looking at one point."""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.poses import look_at


def orbit_poses(n: int, radius: float = 0.9, height: float = 0.7, target=(0.0, 0.0, 0.05),
                start_deg: float = 0.0, span_deg: float = 360.0) -> list[np.ndarray]:
    """n camera-to-world poses evenly spaced over `span_deg` degrees (from `start_deg`) of a horizontal circle
    of `radius` around `target` at z = `height`, each looking at `target`."""
    out = []
    for a in np.deg2rad(start_deg + span_deg * np.arange(n) / max(n, 1)):
        out.append(look_at((radius * np.cos(a) + target[0], radius * np.sin(a) + target[1], height), target))
    return out
