"""`kinfu diff` of a volume with itself (the same file twice, a link to it, or two files holding identical
volumes) finds 0 changes by construction: it warns so, on stderr and in changes.json, and still exits 0."""

from __future__ import annotations

import json
import os

import numpy as np
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, save_ternary


def _grid(obj_x: int = 5) -> TernaryGrid:
    lab = np.full((40, 20, 20), EMPTY, dtype=np.int8)
    lab[:, :, :3] = UNKNOWN  # under the table
    lab[:, :, 3:5] = OCCUPIED  # the table top
    lab[obj_x:obj_x + 8, 4:12, 5:13] = OCCUPIED
    return TernaryGrid(lab, np.zeros(3), 0.01, "world")


def _diff(tmp_path, before, after):
    out = tmp_path / "diff"
    res = CliRunner().invoke(cli, ["diff", str(before), str(after), "-o", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    return res, json.loads((out / "changes.json").read_text())


def test_same_file_twice_warns(tmp_path):
    vol = tmp_path / "volume.npz"
    save_ternary(vol, _grid())
    res, doc = _diff(tmp_path, vol, vol)
    assert doc["counts"]["regions"] == {"removed": 0, "added": 0}
    (warning,) = [w for w in doc["warnings"] if "same file" in w]
    assert str(vol) in warning and "not a finding" in warning
    assert f"kinfu: warning: {warning}" in res.output


def test_a_link_to_the_same_file_warns(tmp_path):
    vol = tmp_path / "volume.npz"
    save_ternary(vol, _grid())
    os.symlink(vol, tmp_path / "link.npz")
    _, doc = _diff(tmp_path, vol, tmp_path / "link.npz")
    assert any("same file" in w for w in doc["warnings"])


def test_identical_volumes_in_two_files_warn(tmp_path):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    save_ternary(a, _grid())
    save_ternary(b, _grid())
    _, doc = _diff(tmp_path, a, b)
    (warning,) = [w for w in doc["warnings"] if "identical volumes" in w]
    assert str(a) in warning and str(b) in warning and "not a finding" in warning


def test_different_volumes_do_not_warn_so(tmp_path):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    save_ternary(a, _grid(5))
    save_ternary(b, _grid(20))  # the object moved
    _, doc = _diff(tmp_path, a, b)
    assert doc["counts"]["regions"] == {"removed": 1, "added": 1}
    assert not any("identical" in w or "same file" in w for w in doc["warnings"])
