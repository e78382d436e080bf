"""Seeded, bounded fuzzing of the three recording containers: damaged copies of the sample MCAP, ROS 1 bag and
ROS 2 bag (bytes flipped, ranges zeroed, the file cut short) through `kinfu info` and a small `kinfu fuse`.

Every run must end with exit 0 (stderr holding at most kinfu's own `kinfu: note:` / `kinfu: warning:` lines),
or exit 2 and exactly one line `kinfu: error: ...`: no traceback, no second line, no Python warning (numpy
RuntimeWarnings included), nothing written to the real stderr by C code (libpng, OpenCV, sqlite), and no
hang (each run has a time limit). The runs are in-process (CliRunner) so the
interpreter and numba's compiled kernels are loaded once; C-level output is caught with capfd.
"""

from __future__ import annotations

import shutil
import signal
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli

SEED = 20261123
MUTATIONS_PER_FORMAT = 20  # x 3 formats = 60 damaged recordings, x 2 commands = 120 runs
RUN_LIMIT_S = 20
FUSE = ["--every", "10", "--size", "1", "--resolution", "32", "--quiet"]


class Hang(BaseException):
    """A run exceeded RUN_LIMIT_S (BaseException: no `except Exception` in the code under test swallows it)."""


def _on_alarm(*_):
    raise Hang()


def mutate(data: bytes, rng: np.random.Generator) -> tuple[bytes, str]:
    """One damaged copy of `data` and what was done to it."""
    buf = bytearray(data)
    kind = int(rng.integers(0, 4))
    if kind == 0:  # scattered bit errors
        at = rng.integers(0, len(buf), int(rng.integers(1, 48)))
        for i in at:
            buf[i] ^= int(rng.integers(1, 256))
        return bytes(buf), f"flip {len(at)} bytes"
    if kind == 1:  # a burst near the start, where headers, schemas and indexes live
        a = int(rng.integers(0, min(len(buf), 8192)))
        n = int(rng.integers(1, 64))
        buf[a:a + n] = rng.integers(0, 256, len(buf[a:a + n]), dtype=np.uint8).tobytes()
        return bytes(buf), f"randomise {n} bytes at {a}"
    if kind == 2:  # a zeroed range (a lost disk block)
        a = int(rng.integers(0, len(buf)))
        n = int(rng.integers(16, 8192))
        buf[a:a + n] = bytes(len(buf[a:a + n]))
        return bytes(buf), f"zero {n} bytes at {a}"
    cut = int(rng.integers(0, len(buf)))  # a copy that stopped early
    return bytes(buf[:cut]), f"truncate to {cut} bytes"


def _cases(sample: Path, tmp: Path) -> list[tuple[Path, str]]:
    """(damaged recording, description) for every format, from one seeded generator."""
    rng = np.random.default_rng(SEED)
    cases = []
    for fmt in ("mcap", "bag", "ros2"):
        for k in range(MUTATIONS_PER_FORMAT):
            if fmt == "ros2":
                target = tmp / f"ros2_{k}"
                shutil.copytree(sample / "recording_ros2", target)
                db = target / "recording_ros2.db3"
                data, what = mutate(db.read_bytes(), rng)
                db.write_bytes(data)
            else:
                target = tmp / f"{fmt}_{k}.{fmt}"
                data, what = mutate((sample / f"recording.{fmt}").read_bytes(), rng)
                target.write_bytes(data)
            cases.append((target, f"{target.name}: {what}"))
    return cases


def _check(res, caught: list, c_stderr: str, what: str) -> None:
    where = f"{what}\n--- output:\n{res.output}\n--- C stderr:\n{c_stderr}"
    assert res.exception is None or isinstance(res.exception, SystemExit), (
        f"{what}: {type(res.exception).__name__}: {res.exception}")
    assert not c_stderr, f"C code wrote to stderr: {where}"
    assert not caught, f"warnings: {[str(w.message) for w in caught]}: {where}"
    assert "Traceback" not in res.output, where
    if res.exit_code == 0:  # success may warn (a damaged recording can give a cut scene), in kinfu's own lines
        assert all(line.startswith(("kinfu: warning: ", "kinfu: note: ")) for line in res.stderr.splitlines()
                   if line.strip()), where
        return
    assert res.exit_code == 2, where
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: "), where


def test_damaged_recordings_end_in_exit_0_or_one_error_line(sample_dir, tmp_path, capfd):
    cases = _cases(sample_dir, tmp_path)
    old = signal.signal(signal.SIGALRM, _on_alarm)
    outcomes: dict[str, int] = {}
    started = time.perf_counter()
    try:
        for path, what in cases:
            for args in (["info", str(path)], ["fuse", str(path), "-o", str(tmp_path / "out"), *FUSE]):
                shutil.rmtree(tmp_path / "out", ignore_errors=True)
                capfd.readouterr()
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    signal.alarm(RUN_LIMIT_S)
                    try:
                        res = CliRunner().invoke(cli, args)
                    except Hang:
                        pytest.fail(f"{what}: kinfu {args[0]} still running after {RUN_LIMIT_S} s")
                    finally:
                        signal.alarm(0)
                _check(res, [w for w in caught if not issubclass(w.category, DeprecationWarning)],
                       capfd.readouterr().err, f"kinfu {args[0]} on {what}")
                key = f"{args[0]} exit {res.exit_code}"
                outcomes[key] = outcomes.get(key, 0) + 1
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    # the fuzzing reached both ends: some damaged copies still read, some are refused
    assert outcomes.get("info exit 2", 0) > 0 and outcomes.get("info exit 0", 0) > 0, outcomes
    assert time.perf_counter() - started < 600, outcomes
