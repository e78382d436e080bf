"""Never destroy what is not kinfu's: inputs, user folders and files are refused unless --force (inputs
always), kinfu replaces only its own files, and a killed run leaves nothing that looks complete."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.core.ownership import MANIFEST

REPO = Path(__file__).resolve().parents[2]
REC = REPO / "sample_data" / "tabletop" / "recording.mcap"
TRAJ = REPO / "sample_data" / "tabletop" / "ground_truth" / "hand.traj"


def run(*args, cwd=None):
    old = os.getcwd()
    if cwd:
        os.chdir(cwd)
    try:
        return CliRunner().invoke(cli, [str(a) for a in args])
    finally:
        os.chdir(old)


def test_export_into_a_users_folder_is_refused_and_leaves_it_untouched(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    one_line_error(run("export", REC, "-o", mine, "--every", "20"), "--out", "kinfu did not write", "--force")
    assert [p.name for p in mine.iterdir()] == ["thesis.tex"]
    # with --force the frames land there and the user's file stays
    assert run("export", REC, "-o", mine, "--every", "20", "--force").exit_code == 0
    assert (mine / "thesis.tex").read_text() == "precious" and (mine / "frames.json").exists()


@pytest.mark.parametrize("out", [".", ""])
def test_export_to_the_current_folder_or_nowhere_is_refused_even_with_force(tmp_path, out):
    (tmp_path / "notes.txt").write_text("keep")
    one_line_error(run("export", REC, "-o", out, "--force", cwd=tmp_path), "--out")
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def test_an_input_is_never_an_output(tmp_path):
    traj = tmp_path / "hand.traj"
    shutil.copy(TRAJ, traj)
    before = traj.read_bytes()
    one_line_error(run("poi", traj, "-o", traj, "--force"), "--output", "is also an input")
    assert traj.read_bytes() == before
    rec = tmp_path / "rec.mcap"
    shutil.copy(REC, rec)
    one_line_error(run("export", rec, "-o", tmp_path, "--force"), "--out", "contains the input")
    assert rec.read_bytes() == REC.read_bytes()


def test_kinfu_replaces_its_own_outputs_but_not_a_users_file(tmp_path):
    out = tmp_path / "pois.json"
    assert run("poi", TRAJ, "-o", out).exit_code == 0
    assert run("poi", TRAJ, "-o", out, "--algorithm", "zvc").exit_code == 0  # its own file: replaced
    assert json.loads(out.read_text())["algorithm"] == "zvc"
    user = tmp_path / "notes.json"
    user.write_text("{}")
    one_line_error(run("poi", TRAJ, "-o", user), "--output", "kinfu did not write")
    assert user.read_text() == "{}"


def test_fuse_replaces_its_folder_whole_keeping_user_files(tmp_path):
    out = tmp_path / "fuse"
    args = ["fuse", REC, "-o", out, "--end", "6.1", "--every", "6", "--size", "1.5", "--resolution", "64", "--quiet"]
    assert run(*args).exit_code == 0
    (out / "my_notes.txt").write_text("mine")
    assert run(*args, "--plot").exit_code == 0
    names = {p.name for p in out.iterdir()}
    assert {"report.json", "volume.npz", "mesh.ply", "my_notes.txt", MANIFEST, "slices_xy.png"} <= names
    assert (out / "my_notes.txt").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST, "fuse"]  # no debris beside it


@pytest.mark.parametrize("moment", ["while fusing", "while writing"])
def test_a_killed_fuse_leaves_the_previous_result_whole(tmp_path, moment):
    out = tmp_path / "fuse"
    base = ["fuse", REC, "-o", out, "--size", "1.5", "--quiet"]
    assert run(*base, "--resolution", "64", "--end", "6.1", "--every", "6").exit_code == 0
    first = (out / "report.json").read_bytes()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    # 512^3 over the whole sample: about 6 s on an idle 2-core machine, so a kill at 2 s lands mid-fusion
    proc = subprocess.Popen([sys.executable, "-m", "kinfu_cli", *map(str, base), "--resolution", "512"], cwd=tmp_path,
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    if moment == "while fusing":
        time.sleep(2.0)
    else:  # as soon as the new folder is being written beside the old one
        while not list(tmp_path.glob(".fuse.*.part")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
    assert proc.poll() is None, "the run ended before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert (out / "report.json").read_bytes() == first  # old result untouched, nothing mixed in
    assert {p.name for p in out.iterdir()} == {MANIFEST, "report.json", "volume.npz", "ternary.npz", "mesh.ply",
                                               "cloud.ply", "trajectory.tum"}
    # the next run cleans the debris of the killed one
    assert run(*base, "--resolution", "64", "--end", "6.1", "--every", "6").exit_code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST, "fuse"]
