"""A damaged labels .npz given to `kinfu eval segment --ground-truth` is one error line naming the file and what
was expected: a truncated archive, a damaged member, a single .npy, wrong arrays, wrong dtypes or shapes (it
tracebacked on a truncated file, and complex points were cast with numpy's warning on stderr)."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli

EXPECTED = "expected a .npz archive of arrays 'points' (N, 3) and 'labels' (N,)"


def _good(path, n=40):
    rng = np.random.default_rng(0)
    np.savez(path, points=rng.random((n, 3)), labels=np.arange(n) % 3)
    return path


def _truncated(path):
    data = _good(path.with_name("whole.npz")).read_bytes()
    path.write_bytes(data[:len(data) // 2])


def _damaged_member(path):
    npy = io.BytesIO()
    np.save(npy, np.random.default_rng(1).random((500, 3)))
    labels = io.BytesIO()
    np.save(labels, np.zeros(500, dtype=np.int64))
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("points.npy", npy.getvalue()[:1000])  # the array's data cut short
        zf.writestr("labels.npy", labels.getvalue())


def _crc(path):
    data = bytearray(_good(path.with_name("whole.npz")).read_bytes())
    data[100:140] = b"\xff" * 40
    path.write_bytes(bytes(data))


CASES = {
    "truncated": (_truncated, "truncated or not a .npz"),
    "empty": (lambda p: p.write_bytes(b""), "truncated or not a .npz"),
    "damaged member": (_damaged_member, "truncated or damaged"),
    "bad crc": (_crc, "truncated or damaged"),
    "single npy": (lambda p: p.write_bytes(_npy_bytes()), "found a single .npy array"),
    "wrong arrays": (lambda p: np.savez(p, a=np.zeros(3)), "found a"),
    "string points": (lambda p: np.savez(p, points=np.array(["a", "b", "c"]), labels=np.zeros(3, int)),
                      "expected points of real numbers"),
    "complex points": (lambda p: np.savez(p, points=np.zeros((5, 3)) + 1j, labels=np.zeros(5, int)),
                       "expected points of real numbers"),
    "2-d labels": (lambda p: np.savez(p, points=np.zeros((5, 3)), labels=np.zeros((5, 2), int)),
                   "expected labels of shape (N,) or (N, 1)"),
    "scalar labels": (lambda p: np.savez(p, points=np.zeros((5, 3)), labels=np.int64(3)),
                      "expected labels of shape (N,) or (N, 1)"),
    "object labels": (lambda p: np.savez(p, points=np.zeros((5, 3)), labels=np.array([None] * 5, dtype=object)),
                      "truncated or damaged"),
}


def _npy_bytes() -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.zeros((4, 3)))
    return buf.getvalue()


@pytest.mark.parametrize("case", list(CASES))
def test_damaged_ground_truth_npz_is_one_error_line(tmp_path, case):
    make, detail = CASES[case]
    labels = tmp_path / "labels.npz"
    make(labels)
    res = CliRunner().invoke(cli, ["eval", "segment", str(_good(tmp_path / "segments.npz")),
                                   "--ground-truth", str(labels)])
    line = one_line_error(res, str(labels), detail)
    if detail.startswith(("truncated", "found")):
        assert EXPECTED in line
    assert "Warning" not in res.output


def test_a_good_npz_still_scores(tmp_path):
    seg = _good(tmp_path / "segments.npz")
    res = CliRunner().invoke(cli, ["eval", "segment", str(seg), "--ground-truth", str(seg), "--json"])
    assert res.exit_code == 0, res.output
    assert '"object_recall": 1.0' in res.output
