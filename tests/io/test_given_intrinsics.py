"""A recording without its CameraInfo (only the image topics were recorded): the intrinsics can be given."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error
from recordings import K, depth_mm, make_recording

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.io.frames import iter_frames
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles


def test_frames_with_given_intrinsics(tmp_path):
    with open_recording(make_recording(tmp_path / "noinfo.mcap", n=3, info=False)) as rec:
        roles = detect_roles(rec, intrinsics="30,30,9.5,7.5")
        assert roles.info_topic is None and roles.intrinsics == (30.0, 30.0, 9.5, 7.5)
        frames = list(iter_frames(rec, roles))
    assert len(frames) == 3
    np.testing.assert_array_equal(frames[0].K, K)
    np.testing.assert_array_equal(frames[1].depth, depth_mm(1).astype(np.float32) * np.float32(0.001))


@pytest.mark.parametrize("bad", ["30,30,9.5", "30,0,9.5,7.5", "nan,30,9.5,7.5", "a,b,c,d"])
def test_bad_intrinsics_name_the_parameter(tmp_path, bad):
    with open_recording(make_recording(tmp_path / "r.mcap", n=2)) as rec:
        with pytest.raises(ConfigError) as err:
            detect_roles(rec, intrinsics=bad)
    assert err.value.parameter == "intrinsics"


def test_fuse_and_info_take_intrinsics(tmp_path):
    rec = make_recording(tmp_path / "noinfo.mcap", n=4, info=False)
    out = tmp_path / "fused"
    res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(out), "--voxel-size", "0.02", "--quiet",
                                   "--pose", "forced", "--intrinsics", "30,30,9.5,7.5"])
    assert res.exit_code == 0, res.output
    report = json.loads((out / "report.json").read_text())
    assert report["intrinsics"]["fx"] == 30.0 and report["frames"]["used"] == 4
    one_line_error(CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(tmp_path / "no"), "--quiet"]),
                   "no sensor_msgs/CameraInfo topic", "--intrinsics")
    one_line_error(CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(tmp_path / "bad"), "--quiet",
                                            "--intrinsics", "30,30"]), "--intrinsics", "fx,fy,cx,cy")
    res = CliRunner().invoke(cli, ["info", str(rec), "--frames", "-q", "--intrinsics", "30,30,9.5,7.5"])
    assert res.exit_code == 0 and "4 usable of 4" in res.output, res.output


def test_focal_lengths_not_in_pixels_are_refused_naming_where_they_came_from(tmp_path):
    # normalised (fx ~ 0.9 for 64 px) or near-zero focal lengths: a field of view near 180 deg. They used to run
    # on, into a 3.5 km grid or an error blaming --size / --origin
    from kinfu_cli.core.camera import field_of_view_problem
    from kinfu_cli.core.camera import intrinsics_matrix as Km

    assert field_of_view_problem(Km(0.9, 0.9, 0.5, 0.5), 64, 48) is not None
    assert field_of_view_problem(Km(1e-9, 1e-9, 31.5, 23.5), 64, 48) is not None
    assert field_of_view_problem(Km(58.5, 58.5, 31.5, 23.5), 64, 48) is None  # the Kinect's 57 deg
    assert field_of_view_problem(Km(160.0, 160.0, 319.5, 239.5), 640, 480) is None  # a 127 deg wide lens
    assert field_of_view_problem(Km(0.9, 0.9, 0.5, 0.5), 0, 0) is None  # size unknown: nothing to say
    rec = make_recording(tmp_path / "noinfo.mcap", n=2, info=False)
    res = CliRunner().invoke(cli, ["fuse", str(rec), "-o", str(tmp_path / "o"), "--intrinsics", "0.4,0.4,0.5,0.5",
                                   "--quiet"])
    one_line_error(res, "--intrinsics", "field of view", "expected focal lengths in pixels")
    assert not (tmp_path / "o").exists()
