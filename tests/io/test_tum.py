"""TUM trajectory files (io/tum.py): exact round trip of stamps and poses, and bad lines named by file and line."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinfu_cli.core.errors import TrajectoryError
from kinfu_cli.io.tum import read_tum, tum_lines, write_tum


def _poses(n: int, seed: int = 3) -> np.ndarray:
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    T[:, :3, 3] = np.random.default_rng(seed).uniform(-5, 5, (n, 3))
    return T


def test_round_trip_keeps_nanosecond_stamps_and_poses(tmp_path):
    T = _poses(50)
    stamps = 1_767_225_600_000_000_000 + np.arange(50) * 33_333_333 + 7  # a 2026 stamp: float64 seconds lose ns
    write_tum(tmp_path / "t.tum", stamps, T, comment="test\nsecond line")
    got_stamps, got = read_tum(tmp_path / "t.tum")
    assert np.array_equal(got_stamps, stamps)
    assert np.abs(got - T).max() < 1e-8
    lines = (tmp_path / "t.tum").read_text().splitlines()
    assert lines[0] == "# timestamp tx ty tz qx qy qz qw" and lines[1:3] == ["# test", "# second line"]
    # the format evo reads: 8 numbers, quaternion x y z w last (w >= 0, unit norm)
    row = np.array(lines[3].split(), dtype=float)
    assert row.shape == (8,) and row[0] == pytest.approx(stamps[0] * 1e-9)
    assert np.allclose(row[1:4], T[0, :3, 3], atol=1e-9) and row[7] >= 0 and np.linalg.norm(row[4:]) == pytest.approx(1)
    assert np.allclose(Rotation.from_quat(row[4:]).as_matrix(), T[0, :3, :3], atol=1e-8)


def test_empty_trajectory_is_a_header_only_file(tmp_path):
    write_tum(tmp_path / "e.tum", [], np.zeros((0, 4, 4)))
    s, T = read_tum(tmp_path / "e.tum")
    assert s.shape == (0,) and T.shape == (0, 4, 4)


@pytest.mark.parametrize("line", ["1.0 0 0 0 0 0 0", "1.0 0 0 0 0 0 0 nan", "1.0 0 0 0 a 0 0 1", "1 0 0 0 0 0 0 0"])
def test_bad_line_is_named(tmp_path, line):
    p = tmp_path / "bad.tum"
    p.write_text("# ok\n0.5 0 0 0 0 0 0 1\n" + line + "\n")
    with pytest.raises(TrajectoryError, match="bad.tum"):
        read_tum(p)


def test_mismatched_lengths_and_non_rigid_poses_refused():
    with pytest.raises(TrajectoryError):
        tum_lines([1, 2], _poses(3))
    bad = _poses(1)
    bad[0, :3, :3] *= 2
    with pytest.raises(Exception, match="rigid"):
        tum_lines([1], bad)
