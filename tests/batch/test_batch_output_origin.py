"""batch's errors about its output folder name where the folder came from: the plan file's `output` key, or
--output. Before, the bag-folder and ownership checks said `--output` (or nothing) for a folder the plan named,
and the user looked for an option they never gave."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli


def _listing(folder: Path) -> list:
    return sorted((str(p.relative_to(folder)), p.stat().st_size) for p in folder.rglob("*"))


@pytest.fixture
def workspace(tmp_path) -> Path:
    """A ROS 2 bag folder recording and a plain recording file (empty: nothing is read before the checks)."""
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (tmp_path / "bag" / "bag_0.db3").write_bytes(b"")
    (tmp_path / "a.mcap").write_bytes(b"")
    return tmp_path


def _refused(ws: Path, case: str) -> tuple[Path, str]:
    """The output folder of the case and what the error says about it."""
    if case == "inside a bag":
        return ws / "bag" / "batch", f"is inside the input folder {ws / 'bag'}; write it elsewhere"
    out = ws / "out"
    out.mkdir()
    if case == "a user's folder":
        (out / "notes.txt").write_text("mine")
        return out, f"{out}: an existing folder that kinfu did not write"
    (out / "manifest.json").write_text("mine")  # a user's manifest.json where batch writes its own
    return out, f"{out / 'manifest.json'}: an existing file that kinfu did not write"


@pytest.mark.parametrize("case", ["inside a bag", "a user's folder", "a user's manifest.json"])
@pytest.mark.parametrize("origin", ["plan", "option"])
def test_output_errors_name_the_plan_key_or_the_option(workspace, connects, case, origin):
    out, what = _refused(workspace, case)
    plan = workspace / "plan.toml"
    key = f'output = "{out}"\n' if origin == "plan" else ""
    plan.write_text(f'{key}stages = ["poi"]\nrecordings = ["bag", "a.mcap"]\n')
    before = _listing(workspace)
    args = ["batch", str(plan), "--quiet"] + (["-o", str(out)] if origin == "option" else [])
    line = one_line_error(CliRunner().invoke(cli, args), what)
    if origin == "plan":
        assert line.startswith(f"kinfu: error: {plan}: output: "), line
        assert "--output" not in line, line
    else:
        assert line.startswith("kinfu: error: --output: "), line
        assert str(plan) not in line, line
    assert _listing(workspace) == before and connects == []  # refused before any work, nothing written
