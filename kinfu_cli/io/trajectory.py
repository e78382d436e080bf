"""A timed sequence of poses: the hand trajectory `kinfu poi` reads, or a camera path.

Shared contract between the readers (bags, TF frames, Polhemus .traj) and the attention code.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.errors import TrajectoryError

MAX_POSITION_M = 1e6  # farther from the frame's origin is corrupt data, not a hand or a camera
MAX_TIME_S = 1e9  # relative times beyond ~30 years: corrupt stamps (and their differences would overflow)


@dataclass
class Trajectory:
    """Poses over time.

    t: (N,) seconds, strictly increasing (relative to `t0_ns` when it came from a recording).
    positions: (N, 3) metres in `frame`.
    rotations: (N, 3, 3) rotation matrices, or None when only positions are known.
    """

    t: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray | None = None
    frame: str = ""
    source: str = ""
    t0_ns: int = 0
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, dtype=np.float64).reshape(-1)
        self.positions = np.asarray(self.positions, dtype=np.float64).reshape(-1, 3)
        if self.rotations is not None:
            self.rotations = np.asarray(self.rotations, dtype=np.float64).reshape(-1, 3, 3)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def validate(self, min_samples: int = 2) -> "Trajectory":
        """Raise TrajectoryError unless the trajectory is usable; return self for chaining."""
        name = self.source or "trajectory"
        if len(self) != self.positions.shape[0]:
            raise TrajectoryError(f"{name}: {len(self)} timestamps but {self.positions.shape[0]} positions")
        if len(self) < min_samples:
            raise TrajectoryError(f"{name}: {len(self)} samples, expected at least {min_samples}")
        if not np.all(np.isfinite(self.t)) or not np.all(np.isfinite(self.positions)):
            bad = int(np.flatnonzero(~np.isfinite(self.positions).all(axis=1) | ~np.isfinite(self.t))[0])
            raise TrajectoryError(f"{name}: sample {bad} is not finite (NaN or inf)")
        far = np.abs(self.positions).max(axis=1) > MAX_POSITION_M
        if far.any():
            bad = int(np.flatnonzero(far)[0])
            raise TrajectoryError(f"{name}: sample {bad} is at {self.positions[bad].tolist()} m, more than "
                                  f"{MAX_POSITION_M:g} m from the origin (expected a hand or camera path)")
        if np.abs(self.t).max(initial=0.0) > MAX_TIME_S:
            bad = int(np.flatnonzero(np.abs(self.t) > MAX_TIME_S)[0])
            raise TrajectoryError(f"{name}: sample {bad} has time {self.t[bad]} s, beyond {MAX_TIME_S:g} s")
        if np.any(np.diff(self.t) <= 0):
            bad = int(np.flatnonzero(np.diff(self.t) <= 0)[0]) + 1
            raise TrajectoryError(f"{name}: timestamps not strictly increasing at sample {bad}")
        return self

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0
