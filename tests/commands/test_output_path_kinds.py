"""An output option refuses, before any work, a path naming another kind of file than it writes, and '-': `poi
--plot p.json` wrote a PNG named p.json, `poi -o -` a JSON file named '-', `synth -o x.mcap` and `import -o
x.txt` folders named like files. (batch: tests/batch/test_batch_upfront.py)"""

from __future__ import annotations

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.commands._output_path import output_kind_problem
from kinfu_cli.core.file_kinds import IMAGE_SUFFIXES

REC = "recording.mcap"  # never read: the option is refused first
FOLDER, RECORDING, IMAGE, VIEWER, GEOMETRY, JSON = "out.json", "rec.txt", "plot.json", "viz.txt", "err.json", "r.png"
CASES = [
    (["fuse", REC], "-o", "--output", FOLDER), (["fuse", REC, "-o", "f"], "--viz", "--viz", VIEWER),
    (["poi", REC], "-o", "--output", JSON), (["poi", REC], "--plot", "--plot", IMAGE),
    (["poi", REC], "--viz", "--viz", VIEWER),
    (["segment", "volume.npz"], "-o", "--output", "seg.npz"), (["segment", "volume.npz"], "--viz", "--viz", VIEWER),
    (["nbv", "volume.npz"], "-o", "--output", "views.ply"), (["nbv", "volume.npz"], "--plot", "--plot", IMAGE),
    (["nbv", "volume.npz"], "--viz", "--viz", "views.bag"),
    (["localize", "model.ply", "points.txt"], "-o", "--output", JSON),
    (["grasp", "segments.json"], "-o", "--output", JSON), (["grasp", "segments.json"], "--plot", "--plot", IMAGE),
    (["diff", "a.npz", "b.npz"], "-o", "--output", "changes.json"),
    (["eval", "segment", "seg", "--ground-truth", "gt"], "-o", "--output", JSON),
    (["eval", "segment", "seg", "--ground-truth", "gt"], "--plot", "--plot", IMAGE),
    (["eval", "fusion", "fused", "--ground-truth", "gt"], "-o", "--output", "eval.npz"),
    (["eval", "fusion", "fused", "--ground-truth", "gt"], "--error-mesh", "--error-mesh", GEOMETRY),
    (["eval", "nbv", "gt"], "-o", "--output", JSON), (["eval", "nbv", "gt"], "--plot", "--plot", IMAGE),
    (["eval", "grasp"], "-o", "--output", JSON), (["eval", "localize"], "-o", "--output", JSON),
    (["export", REC], "-o", "--out", FOLDER), (["import", "frames"], "-o", "--out", RECORDING),
    (["synth"], "-o", "--out", "synth.mcap"),
]
IDS = [" ".join(a[:2] + [o]) for a, o, _, _ in CASES]


@pytest.mark.parametrize("args, option, flag, wrong", CASES, ids=IDS)
def test_a_name_of_another_kind_of_file_is_refused_before_any_work(tmp_path, monkeypatch, args, option, flag, wrong):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(cli, [*args, option, wrong])
    one_line_error(res, f"{flag}: {wrong}")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, option, flag, wrong", CASES, ids=IDS)
def test_a_dash_is_refused_not_written_as_a_file(tmp_path, monkeypatch, args, option, flag, wrong):
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(cli, [*args, option, "-"])
    one_line_error(res, f"{flag}: '-' (standard output) is not a path kinfu writes to")
    assert list(tmp_path.iterdir()) == []


def test_the_dash_error_points_to_json_where_the_command_has_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    one_line_error(CliRunner().invoke(cli, ["poi", REC, "-o", "-"]), "--json prints the results on standard output")


@pytest.mark.parametrize("kind, path", [
    ("json", "results.json"), ("json", "results.txt"), ("json", "results"), ("image", "p.png"), ("image", "p.PDF"),
    ("image", "plot"), ("viewer", "v.mcap"), ("geometry", "e.ply"), ("geometry", "e.obj"), ("folder", "out"),
    ("folder", "run.2024-01"), ("recording", "r.mcap"), ("recording", "r.bag"), ("recording", "rosbag2_run"),
    ("trajectory", "gt.tum"), ("trajectory", "gt.txt"), ("trajectory", "gt"),
])
def test_names_of_the_right_kind_pass(kind, path):
    assert output_kind_problem(path, kind) is None


def test_an_existing_folder_where_a_file_goes_is_left_to_the_command(tmp_path):
    (tmp_path / "plots.json").mkdir()  # nbv/eval nbv take a folder for --plot; claim_output judges the folder
    assert output_kind_problem(tmp_path / "plots.json", "image") is None


def test_every_image_suffix_is_a_format_matplotlib_writes():
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    supported = {f".{s}" for s in Figure().canvas.get_supported_filetypes()}
    assert IMAGE_SUFFIXES <= supported


def test_export_trajectory_refuses_a_name_of_another_kind_of_file(tmp_path, monkeypatch):
    """export --trajectory tum -o gt.png wrote TUM text into a .png."""
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(cli, ["export", REC, "--trajectory", "tum", "-o", "gt.png"])
    one_line_error(res, "--out: gt.png names a .png file; the trajectory is TUM text")
    assert list(tmp_path.iterdir()) == []
