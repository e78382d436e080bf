"""Bad inputs found by an adversarial campaign over every command (branch badin): each must end in one
`kinfu: error:` line (exit 2) naming the option or file, with nothing written."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.conftest import one_line_error
from tests.recordings import make_recording


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A fused volume of the tiny test recording and one POI inside it."""
    root = tmp_path_factory.mktemp("tiny")
    rec = make_recording(root / "rec.mcap")
    res = run("fuse", rec, "-o", root / "fuse", "--resolution", "32", "--quiet")
    assert res.exit_code == 0, res.output
    (root / "pois.json").write_text(json.dumps({"pois": [{"position": [0.6, -0.1, 1.8]}]}))
    return root


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e999"])
def test_nbv_refuses_a_table_height_that_is_not_finite(tiny, tmp_path, value):
    res = run("nbv", tiny / "fuse" / "volume.npz", "--pois", tiny / "pois.json", "-o", tmp_path / "v.json",
              "--table-z", value, "--quiet")
    one_line_error(res, "--table-z", "expected")
    assert not (tmp_path / "v.json").exists()


def test_one_path_for_two_outputs_is_refused_before_any_work(tiny, tmp_path):
    same = tmp_path / "same.json"
    res = run("nbv", tiny / "fuse" / "volume.npz", "--pois", tiny / "pois.json", "-o", same, "--plot", same, "--quiet")
    one_line_error(res, "--output/--plot", "given for both")
    assert not same.exists()


def test_a_file_of_an_input_folder_is_never_an_output(tmp_path):
    """eval fusion read out/fuse/mesh.ply and then wrote its JSON over it; import wrote the recording into the
    frame folder it read (where the next import of that folder finds it)."""
    fused = tmp_path / "fuse"
    fused.mkdir()
    (fused / "mesh.ply").write_text("ply\n")
    res = run("eval", "fusion", fused, "--ground-truth", tmp_path / "gt", "-o", fused / "mesh.ply", "--quiet",
              "--force")
    one_line_error(res, "--output", "input folder")
    assert (fused / "mesh.ply").read_text() == "ply\n"
    frames = tmp_path / "frames"
    frames.mkdir()
    res = run("import", frames, "-o", frames / "rec.mcap", "-q")
    one_line_error(res, "--out", "inside the input folder")
    assert not (frames / "rec.mcap").exists()


@pytest.mark.parametrize("option, value", [("--noise", "nan"), ("--noise", "0.01,inf"), ("--speed", "inf"),
                                           ("--speed", "nan")])
def test_eval_poi_refuses_settings_that_are_not_finite(tmp_path, option, value):
    """--noise nan was scored as a setting (exit 0, NaN trajectories)."""
    res = run("eval", "poi", tmp_path, option, value, "--quiet")
    one_line_error(res, option, "finite")


def test_nbv_candidates_far_away_or_in_objects_mode_are_refused(tiny, tmp_path):
    """A candidate 1e300 m away overflowed the ray casts (numpy warnings, exit 0); --mode objects read no
    --candidates file at all, so a damaged one passed silently."""
    far = tmp_path / "far.json"
    far.write_text(json.dumps([[[1, 0, 0, 1e300], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]]))
    vol = tiny / "fuse" / "volume.npz"
    res = run("nbv", vol, "--pois", tiny / "pois.json", "--candidates", far, "-o", tmp_path / "v.json", "--quiet")
    one_line_error(res, str(far), "from the origin")
    res = run("nbv", vol, "--mode", "objects", "--candidates", far, "-o", tmp_path / "v.json", "--quiet")
    one_line_error(res, "--candidates", "--mode poi")
    assert not (tmp_path / "v.json").exists()
