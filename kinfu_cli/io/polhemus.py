"""Polhemus FasTrak hand trajectories (`.traj`) and their hand-labelled changes (`.traj.res`).

Format (hand-polhemus data set, R. Monica, CC0): text, one 4x4 homogeneous transform per sample
(4 lines of 4 numbers, then a blank line), sensor pose in the tracker base frame, metres.
Sampled at 100 Hz without timestamps, so sample i is at t = i / 100 s.
`.traj.res`: one ground-truth change "x y z" (metres, same frame) per line.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.errors import TrajectoryError
from kinfu_cli.io.trajectory import Trajectory

RATE_HZ = 100.0
#: Tolerance on R^T R = I and det R = 1: the files print 6 significant digits.
RIGID_TOL = 1e-3


def _parse_numbers(path: Path) -> np.ndarray:
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise TrajectoryError(f"{path}: no such trajectory file") from None
    except IsADirectoryError:
        raise TrajectoryError(f"{path}: is a folder, expected a .traj file") from None
    except UnicodeDecodeError:
        raise TrajectoryError(f"{path}: not a text file, expected 4x4 matrices as text") from None
    tokens = text.split()
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(i for i, tok in enumerate(tokens) if not _is_float(tok))
        raise TrajectoryError(f"{path}: sample {bad // 16} has a non-numeric value {tokens[bad]!r}") from None


def _is_float(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def read_polhemus_matrices(path: str | os.PathLike) -> np.ndarray:
    """All samples of a `.traj` file as (N, 4, 4) rigid transforms (tracker base <- sensor).

    Raises TrajectoryError naming the file (and the sample) when the file is empty, has fewer than
    2 samples, a count of numbers that is not a multiple of 16, non-finite values, or a matrix that
    is not a rigid transform (rotation not orthonormal with det +1, last row not 0 0 0 1).
    """
    path = Path(path)
    vals = _parse_numbers(path)
    if vals.size == 0:
        raise TrajectoryError(f"{path}: empty trajectory file, expected 4x4 matrices (16 numbers per sample)")
    if vals.size % 16:
        raise TrajectoryError(f"{path}: {vals.size} numbers is not a multiple of 16 "
                              f"(sample {vals.size // 16} is incomplete), expected 4x4 matrices")
    mats = vals.reshape(-1, 4, 4)
    n = mats.shape[0]
    if n < 2:
        raise TrajectoryError(f"{path}: {n} sample, expected at least 2 to form a trajectory")
    finite = np.isfinite(mats).all(axis=(1, 2))
    if not finite.all():
        raise TrajectoryError(f"{path}: sample {int(np.flatnonzero(~finite)[0])} is not finite (NaN or inf)")
    last_ok = np.abs(mats[:, 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=1) <= RIGID_TOL
    rot = mats[:, :3, :3]
    ortho_err = np.abs(np.einsum("nji,njk->nik", rot, rot) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(rot)
    rigid = last_ok & (ortho_err <= 10 * RIGID_TOL) & (np.abs(det - 1.0) <= 10 * RIGID_TOL)
    if not rigid.all():
        i = int(np.flatnonzero(~rigid)[0])
        why = ("last row is not 0 0 0 1" if not last_ok[i]
               else f"rotation is not orthonormal with det +1 (|R^T R - I| = {ortho_err[i]:.3g}, det = {det[i]:.3g})")
        raise TrajectoryError(f"{path}: sample {i} is not a rigid transform: {why}")
    return mats


def read_polhemus(path: str | os.PathLike, rate_hz: float = RATE_HZ) -> Trajectory:
    """Read a Polhemus `.traj` file into a Trajectory (t = i / rate_hz seconds, frame "polhemus_base")."""
    path = Path(path)
    if not rate_hz > 0:
        raise TrajectoryError(f"{path}: sampling rate must be positive, got {rate_hz}")
    mats = read_polhemus_matrices(path)
    n = mats.shape[0]
    traj = Trajectory(t=np.arange(n, dtype=np.float64) / rate_hz, positions=mats[:, :3, 3].copy(),
                      rotations=mats[:, :3, :3].copy(), frame="polhemus_base", source=str(path),
                      meta={"rate_hz": rate_hz, "format": "polhemus-traj"})
    return traj.validate()


def read_ground_truth(path: str | os.PathLike) -> np.ndarray:
    """Read a `.traj.res` file: (M, 3) ground-truth change positions in metres (M may be 0)."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise TrajectoryError(f"{path}: no such ground-truth file (.traj.res)") from None
    rows = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        parts = line.split()
        try:
            row = [float(v) for v in parts]
        except ValueError:
            row = []
        if len(row) != 3 or not np.all(np.isfinite(row)):
            raise TrajectoryError(f"{path}: line {lineno} is not 'x y z' (three finite numbers): {line.strip()!r}")
        rows.append(row)
    return np.array(rows, dtype=np.float64).reshape(-1, 3)


def write_polhemus(path: str | os.PathLike, traj: Trajectory) -> Path:
    """Write a Trajectory as a `.traj` file (identity rotations when it has none), atomically.

    The file has no timestamps: readers assume 100 Hz, so resample first if `traj` is not.
    """
    n = len(traj)
    mats = np.tile(np.eye(4), (n, 1, 1))
    if traj.rotations is not None:
        mats[:, :3, :3] = traj.rotations
    mats[:, :3, 3] = traj.positions
    lines = []
    for m in mats:
        lines.extend(" ".join(f"{v:.6g}" for v in row) for row in m)
        lines.append("")
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return Path(path)
