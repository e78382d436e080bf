"""`kinfu nbv` limits that name what is wrong: the candidate views of a whole run (every POI gets its own sphere,
so 2,000 POIs made 1.9 M poses and a run of many minutes) and a sensor image too large or too wide to cast (a 1e9 px
image ran out of memory, or blamed --vfov-extra, which the user had not given)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, TernaryGrid, save_ternary
from kinfu_cli.nbv.sensor import MAX_IMAGE_PIXELS, camera_from_options
from kinfu_cli.nbv.viewpoints import MAX_RUN_VIEWS, SphereSpec
from kinfu_cli.nbv.workflow import NbvOptions, check_run_size


def _volume_and_pois(tmp_path, n_pois: int = 1):
    lab = np.full((20, 20, 20), EMPTY, np.int8)
    lab[:, :, :4] = OCCUPIED
    vol, pois = tmp_path / "ternary.npz", tmp_path / "pois.json"
    save_ternary(vol, TernaryGrid(lab, np.zeros(3), 0.05))
    pois.write_text(json.dumps({"pois": [{"id": i, "position": [0.5, 0.5, 0.4]} for i in range(n_pois)]}))
    return vol, pois


def test_a_run_of_more_views_than_the_bound_is_refused_naming_the_pois_file(tmp_path):
    n = MAX_RUN_VIEWS // 960 + 1  # 1,042 POIs at the paper's 960 views
    vol, pois = _volume_and_pois(tmp_path, n)
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--quiet", "-o", str(tmp_path / "v.json")])
    one_line_error(res, "--lon-step/--lat-step/--roll-step", str(pois), f"{n:,} POIs x 960", f"{n * 960:,}",
                   f"{MAX_RUN_VIEWS:,}")
    assert not (tmp_path / "v.json").exists()


def test_the_run_bound_counts_candidate_files_per_poi_and_passes_runs_within_it():
    assert check_run_size("pois.json", 1000, NbvOptions()) == 960_000
    coarse = NbvOptions(sphere=SphereSpec(lon_step=60, lat_step=30, roll_step=90))  # 6 x 4 x 4 = 96 views
    assert check_run_size("pois.json", 10_000, coarse) == 960_000
    with pytest.raises(ConfigError) as err:
        check_run_size("pois.json", 3, NbvOptions(candidates="cands.json"), 400_000)
    assert err.value.parameter == "candidates"
    assert "pois.json: 3 POIs x 400,000 candidates in cands.json = 1,200,000" in str(err.value)


def test_a_huge_image_names_its_size_not_vfov_extra(tmp_path):
    vol, pois = _volume_and_pois(tmp_path)
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--quiet", "--fx", "500", "--fy", "500",
                                   "--cx", "5e8", "--cy", "240", "--width", "1000000000", "--height", "480"])
    line = one_line_error(res, "--width/--height", "1000000000x480 px", f"{MAX_IMAGE_PIXELS:,}")
    assert "vfov" not in line


def test_a_sensor_that_widening_turns_past_180_degrees_names_its_intrinsics(tmp_path):
    vol, pois = _volume_and_pois(tmp_path)
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--quiet", "--fx", "100", "--fy", "100",
                                   "--cx", "320", "--cy", "2000"])
    line = one_line_error(res, "--fy/--cy/--height", "fy=100, cy=2000", "87.1 deg above")
    assert not line.startswith("kinfu: error: --vfov-extra")


def test_the_volumes_recorded_camera_is_named_when_it_is_too_large():
    recorded = dict(fx=500.0, fy=500.0, cx=320.0, cy=240.0, width=100_000, height=100_000)
    with pytest.raises(ConfigError) as err:
        camera_from_options(recorded=recorded, recorded_from="scan/volume.npz", vfov_extra_deg=5.0)
    assert "scan/volume.npz: the camera it was fused with" in str(err.value) and "100000x100000 px" in str(err.value)
    assert camera_from_options(recorded=dict(recorded, width=640, height=480)).height == 480


def test_views_times_sensor_pixels_are_bounded_before_any_pose_is_made():
    """The view bound alone let 1,000 POIs at 4096 x 4096 px cast 1.6e13 rays (days); the Kinect's 640 x 480 at
    the view bound is the budget."""
    from kinfu_cli.nbv.workflow import MAX_RUN_RAYS

    assert check_run_size("pois.json", 1000, NbvOptions(), None, 640 * 480) == 960_000  # the bound's own case
    assert 960_000 * 640 * 480 <= MAX_RUN_RAYS
    assert check_run_size("pois.json", 2, NbvOptions(), None, 4096 * 4096) == 1920
    with pytest.raises(ConfigError) as err:
        check_run_size("pois.json", 20, NbvOptions(), None, 4096 * 4096)
    assert "sensor pixels" in str(err.value) and err.value.parameter is None  # the image may be the volume's
