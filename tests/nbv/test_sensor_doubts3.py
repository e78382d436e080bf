"""An NBV sensor whose principal point lies far outside its image is refused naming where it came from (the views
of `--cy 5000` in a 480 px image looked 83 deg past their POI, saw nothing, and only a generic warning followed)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, TernaryGrid, save_ternary
from kinfu_cli.nbv.sensor import camera_from_options


def _volume_and_pois(tmp_path):
    lab = np.full((20, 20, 20), EMPTY, np.int8)
    lab[:, :, :4] = OCCUPIED
    vol, pois = tmp_path / "ternary.npz", tmp_path / "pois.json"
    save_ternary(vol, TernaryGrid(lab, np.zeros(3), 0.05))
    pois.write_text(json.dumps({"pois": [{"id": 0, "position": [0.5, 0.5, 0.4]}]}))
    return vol, pois


def test_a_principal_point_far_below_the_image_names_the_options(tmp_path):
    vol, pois = _volume_and_pois(tmp_path)
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--quiet", "-o", str(tmp_path / "v.json"),
                                   "--fx", "525", "--fy", "525", "--cx", "320", "--cy", "5000"])
    line = one_line_error(res, "--cx/--cy", "cy=5000 is outside [-240, 720]", "480 px")
    assert "cx=" not in line
    assert not (tmp_path / "v.json").exists()


def test_the_volumes_recorded_camera_is_named_when_its_principal_point_is_outside():
    recorded = dict(fx=500.0, fy=500.0, cx=-400.0, cy=240.0, width=640, height=480)
    with pytest.raises(ConfigError) as err:
        camera_from_options(recorded=recorded, recorded_from="scan/volume.npz")
    assert "scan/volume.npz: the camera it was fused with" in str(err.value)
    assert "cx=-400 is outside [-320, 960]" in str(err.value)


@pytest.mark.parametrize("cx, cy", [(320.0, 240.0), (-300.0, 700.0), (950.0, -230.0)])
def test_a_principal_point_within_half_an_image_of_it_is_accepted(cx, cy):
    cam = camera_from_options(fx=525.0, fy=525.0, cx=cx, cy=cy, vfov_extra_deg=0.0)
    assert (cam.cx, cam.cy) == (cx, cy)
