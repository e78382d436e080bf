"""An output inside an input ROS 2 bag folder: `kinfu fuse`, `poi` (and nbv --camera-info, batch) wrote into the bag
folder with exit 0, where `kinfu export` refused. A recording that is a folder is one input: writing anywhere
inside it changes the input, so every command refuses it before any work, as export does, naming the option. A
new output beside a recording file in a plain folder stays allowed."""

from __future__ import annotations

import shutil

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.commands._options import claim_outputs


def _listing(folder):
    return sorted((p.relative_to(folder), p.stat().st_size) for p in folder.rglob("*"))


@pytest.fixture
def bag(sample_dir, tmp_path):
    rec = tmp_path / "bag"
    shutil.copytree(sample_dir / "recording_ros2", rec)
    return rec


@pytest.mark.parametrize("args, flag", [
    (["fuse", "{bag}", "-o", "{bag}/out", "--voxel-size", "0.02", "--quiet"], "--output"),
    (["fuse", "{bag}", "-o", "{tmp}/out", "--viz", "{bag}/f.mcap", "--quiet"], "--viz"),
    (["poi", "{bag}", "-o", "{bag}/pois.json", "--quiet"], "--output"),
    (["poi", "{bag}/recording_ros2.db3", "-o", "{bag}/sub/pois.json", "--quiet"], "--output"),
    (["poi", "{bag}", "-o", "{tmp}/p.json", "--plot", "{bag}/p.png", "--quiet"], "--plot"),
    (["export", "{bag}", "-o", "{bag}/frames", "-q"], "--out"),
])
def test_an_output_inside_the_bag_folder_is_refused(bag, tmp_path, args, flag):
    before = _listing(bag)
    res = CliRunner().invoke(cli, [a.format(bag=bag, tmp=tmp_path) for a in args])
    line = one_line_error(res, flag, f"is inside the input folder {bag}; write it elsewhere")
    assert "Traceback" not in line
    assert _listing(bag) == before


def test_batch_output_inside_a_bag_recording_is_refused(bag, tmp_path):
    plan = tmp_path / "plan.toml"
    plan.write_text(f'output = "{bag}/batch"\nstages = ["poi"]\nrecordings = ["{bag}"]\n')
    before = _listing(bag)
    one_line_error(CliRunner().invoke(cli, ["batch", str(plan), "--quiet"]), "inside the input folder")
    assert _listing(bag) == before


def test_outputs_beside_a_recording_file_in_a_plain_folder_stay_allowed(sample_dir, tmp_path):
    shutil.copy(sample_dir / "recording.mcap", tmp_path / "rec.mcap")
    claim_outputs({"output": tmp_path / "pois.json", "outdir": tmp_path / "fuse"}, [tmp_path / "rec.mcap"], False,
                  recordings=[tmp_path / "rec.mcap"])


def test_poi_of_the_bag_writing_elsewhere_still_works(bag, tmp_path):
    res = CliRunner().invoke(cli, ["poi", str(bag), "-o", str(tmp_path / "pois.json"), "--quiet"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "pois.json").is_file()
