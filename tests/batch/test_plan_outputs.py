"""A plan entry's `output` must be one folder name beside the others: a YAML boolean or list (`output: true`,
`output: [a, b]`) made a folder named True or "['a', 'b']", and a recording's folder inside another's
(`x` and `x/fuse`) had its outputs written into the other's fuse output, which that recording replaces."""

from __future__ import annotations

import pytest

from kinfu_cli.batch.plan import load_plan
from kinfu_cli.batch.stages import RECORDING, StageRun, StageSpec
from kinfu_cli.core.errors import ConfigError

TABLE = {"fuse": StageSpec("fuse", (), (RECORDING,), ("fuse.json",), ("fuse.json",), lambda rec, options: None,
                           lambda rec, options, force: StageRun())}


@pytest.fixture
def folder(tmp_path):
    for name in ("a.mcap", "b.mcap"):
        (tmp_path / name).write_bytes(b"x")
    return tmp_path


@pytest.mark.parametrize("entries, needles", [
    ("[{path: a.mcap, output: true}]", ["recordings[0]", "output True", "folder name"]),
    ("[{path: a.mcap, output: [x, y]}]", ["recordings[0]", "output ['x', 'y']", "folder name"]),
    ("[{path: a.mcap, output: {x: 1}}]", ["recordings[0]", "folder name"]),
    ("[{path: a.mcap, output: x}, {path: b.mcap, output: x/fuse}]", ["recordings[1]", "lies inside", "side by side"]),
    ("[{path: a.mcap, output: x/deep/er}, {path: b.mcap, output: x}]", ["recordings[0]", "lies inside"]),
])
def test_bad_entry_outputs_are_refused(folder, entries, needles):
    plan = folder / "plan.yaml"
    plan.write_text(f"output: out\nstages: [fuse]\nrecordings: {entries}\n")
    with pytest.raises(ConfigError) as info:
        load_plan(plan, TABLE, None)
    for n in needles:
        assert n in str(info.value), str(info.value)


def test_side_by_side_and_numbered_outputs_are_fine(folder):
    plan = folder / "plan.yaml"
    plan.write_text("output: out\nstages: [fuse]\nrecordings: [{path: a.mcap, output: x}, {path: b.mcap, "
                    "output: 2024}, {path: b.mcap, output: xy}]\n")
    outs = [r.output for r in load_plan(plan, TABLE, None).recordings]
    assert outs == [folder / "out/x", folder / "out/2024", folder / "out/xy"]
