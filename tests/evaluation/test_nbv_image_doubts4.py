"""`kinfu eval nbv` bounds its sensor image as `kinfu nbv` does (nbv.sensor.MAX_IMAGE_PIXELS): 8192x8192 took
18 GB within 90 s where kinfu nbv refuses it."""

from __future__ import annotations

import dataclasses

import open3d as o3d
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.nbv_loop import LoopConfig, _sensor_setup, load_scene
from kinfu_cli.nbv.sensor import MAX_IMAGE_PIXELS


def _box(tmp_path):
    path = tmp_path / "box.ply"
    o3d.io.write_triangle_mesh(str(path), o3d.geometry.TriangleMesh.create_box(0.3, 0.3, 0.3))
    return path


def test_an_image_over_the_nbv_bound_is_refused_up_front(tmp_path):
    mesh = _box(tmp_path)
    res = CliRunner().invoke(cli, ["eval", "nbv", str(mesh), "--poi", "0.1", "0.1", "0.1", "--strategy", "fixed",
                                   "--views", "1", "--quiet", "-o", str(tmp_path / "e.json"), "--width", "8192",
                                   "--height", "8192"])
    one_line_error(res, "--width/--height", "8192x8192", "4096x4096")
    assert not (tmp_path / "e.json").exists()


def test_the_bound_is_the_nbv_one():
    LoopConfig(strategies=("fixed",), width=4096, height=4096).check()
    with pytest.raises(ConfigError) as err:
        LoopConfig(strategies=("fixed",), width=4096, height=4097).check()
    assert err.value.parameter == "width/height" and f"{MAX_IMAGE_PIXELS:,}" in str(err.value)


def test_a_width_given_with_the_scene_height_is_bounded_too(tmp_path):
    cfg = LoopConfig(strategies=("fixed",), poi=(0.1, 0.1, 0.1), width=8192)
    sc = load_scene(_box(tmp_path), cfg)
    _sensor_setup(sc, cfg)  # 8192 x the scene's 480
    sc = dataclasses.replace(sc, width=4000, height=3000)
    with pytest.raises(ConfigError, match=r"the sensor's image size 8192x3000 px"):
        _sensor_setup(sc, cfg)
