"""Camera paths for synthetic frames that need no robot: poses on a circle, all looking at one point; a hand-held
walk through the synthetic room (sim.room)."""

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


def room_walk_poses(n: int, seed: int) -> list[np.ndarray]:
    """Camera poses (sim.room's z-up room frame) of a hand-held walk at 30 Hz: 0.24 m/s along x, a 150 degree pan
    from the corner with the furniture towards the bare walls, with wobble and a random walk (the seed's). Where
    the view holds one wall, the floor and a table edge, depth alone lets a tracker slide along the wall."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 30.0
    eye = np.stack([-1.2 + 0.24 * t, -0.6 + 0.05 * np.sin(1.3 * t), 1.45 + 0.04 * np.sin(2.1 * t)], 1)
    eye += np.cumsum(rng.normal(0, 0.0008, (n, 3)), 0)
    yaw = np.radians(20.0 + 150 * t / t[-1]) + 0.05 * np.sin(3.0 * t)
    pitch = np.radians(-25 + 8 * np.sin(0.9 * t))
    fwd = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], 1)
    return [look_at(e, e + d) for e, d in zip(eye, fwd)]
