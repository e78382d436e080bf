"""An empty output path ('' from a script's unset variable) is refused as empty, naming the option, by every
command: click would make it Path('.'), and the error spoke of the current folder instead."""

from __future__ import annotations

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli

REC = "recording.mcap"  # never read: the option is refused first
CASES = [
    (["fuse", REC], "-o", "--output"), (["fuse", REC, "-o", "f"], "--viz", "--viz"),
    (["poi", REC], "-o", "--output"), (["poi", REC], "--plot", "--plot"), (["poi", REC], "--viz", "--viz"),
    (["segment", "volume.npz"], "-o", "--output"), (["segment", "volume.npz"], "--viz", "--viz"),
    (["nbv", "volume.npz"], "-o", "--output"), (["nbv", "volume.npz"], "--plot", "--plot"),
    (["nbv", "volume.npz"], "--viz", "--viz"),
    (["localize", "model.ply", "points.txt"], "-o", "--output"),
    (["grasp", "segments.json"], "-o", "--output"), (["grasp", "segments.json"], "--plot", "--plot"),
    (["diff", "a.npz", "b.npz"], "-o", "--output"),
    (["eval", "segment", "seg", "--ground-truth", "gt"], "-o", "--output"),
    (["eval", "segment", "seg", "--ground-truth", "gt"], "--plot", "--plot"),
    (["eval", "fusion", "fused", "--ground-truth", "gt"], "-o", "--output"),
    (["eval", "fusion", "fused", "--ground-truth", "gt"], "--error-mesh", "--error-mesh"),
    (["eval", "nbv", "gt"], "-o", "--output"), (["eval", "nbv", "gt"], "--plot", "--plot"),
    (["eval", "grasp"], "-o", "--output"), (["eval", "localize"], "-o", "--output"),
    (["batch", "plan.toml"], "-o", "--output"),
    (["export", REC], "-o", "--out"), (["import", "frames"], "-o", "--out"), (["synth"], "-o", "--out"),
]


@pytest.mark.parametrize("args, option, flag", CASES, ids=[" ".join(a[:2] + [o]) for a, o, _ in CASES])
def test_an_empty_output_path_is_refused_as_empty(tmp_path, monkeypatch, args, option, flag):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(cli, [*args, option, ""])
    one_line_error(res, f"{flag}: expected a path, got an empty one")
    assert list(tmp_path.iterdir()) == []
