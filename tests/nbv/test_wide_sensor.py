"""A 100000 x 2 px sensor (within the pixel bound) ran `kinfu nbv` out of memory: widening it by vfov_extra_deg
adds fy tan(5 deg) rows whatever its height (8752 rows at fy = 50000), and its rolled windows' shared lattice spans
the window's width squared. The widened image is bounded (MAX_CAST_PIXELS) naming the intrinsics' source, and a
shared lattice larger than the windows it serves gives way to one lattice per view."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, save_ternary
from kinfu_cli.nbv import raycast
from kinfu_cli.nbv.raycast import RayVolume, cast_views
from kinfu_cli.nbv.sensor import MAX_CAST_PIXELS, camera_from_options
from kinfu_cli.nbv.viewpoints import sphere_viewpoints

WIDE = dict(fx=50000.0, fy=50000.0, cx=50000.0, cy=1.0, width=100_000, height=2)


def test_a_few_rows_widened_into_thousands_are_refused_by_the_cli(tmp_path):
    lab = np.full((20, 20, 20), EMPTY, np.int8)
    lab[:, :, :4] = OCCUPIED
    vol, pois = tmp_path / "ternary.npz", tmp_path / "pois.json"
    save_ternary(vol, TernaryGrid(lab, np.zeros(3), 0.05))
    pois.write_text(json.dumps({"pois": [{"id": 0, "position": [0.5, 0.5, 0.4]}]}))
    args = [f"--{k}={v:g}" for k, v in WIDE.items()]
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--quiet", "-o", str(tmp_path / "v.json"),
                                   *args])
    one_line_error(res, "--fy/--height/--vfov-extra", "the given 100000x2 px image at fy=50000",
                   "cast as 100000x8752 px: 875,200,000 pixels", f"{MAX_CAST_PIXELS:,}")
    assert not (tmp_path / "v.json").exists()


def test_the_widened_bound_names_the_recorded_camera_and_keeps_real_sensors():
    with pytest.raises(ConfigError) as err:
        camera_from_options(recorded=WIDE, recorded_from="scan/volume.npz", vfov_extra_deg=5.0)
    assert err.value.parameter == "fy/height/vfov_extra_deg"
    assert str(err.value).startswith("fy/height/vfov_extra_deg: scan/volume.npz: the camera it was fused with")
    assert camera_from_options(vfov_extra_deg=0.0, **WIDE).widened().height == 2  # not widened: cast as it is
    big = camera_from_options(fx=3400, fy=3400, cx=2047.5, cy=2047.5, width=4096, height=4096, vfov_extra_deg=5.0)
    assert big.widened().height == 4952  # the largest sensor image still casts, widened
    assert camera_from_options(vfov_extra_deg=5.0).widened().height == 596  # the Kinect v1 preset


def test_rolls_of_a_wide_short_window_are_cast_on_lattices_of_their_own(monkeypatch):
    lab = np.full((40, 40, 40), EMPTY, np.int8)
    lab[15:25, 15:25, 15:25] = UNKNOWN
    vol = RayVolume.from_grid(TernaryGrid(lab, np.zeros(3), 0.025))
    poi = np.array([0.5, 0.5, 0.5])
    cam = CameraModel(2000.0, 2000.0, 1999.5, 0.5, 4000, 2, min_range=0.2, max_range=4.0)
    poses = sphere_viewpoints(poi, 0.8, lon_step=120, lat_max=30, lat_step=30, roll_step=45)  # 8 rolls a position
    seen = []
    cast_batch = raycast._cast_batch

    def record(vol, cam, center, radius, r_ext, flags, p_unknown, batch, *rest):
        seen.extend(batch)
        return cast_batch(vol, cam, center, radius, r_ext, flags, p_unknown, batch, *rest)

    monkeypatch.setattr(raycast, "_cast_batch", record)
    shared = cast_views(vol, poses, cam, poi, 0.2)
    # the 45-deg rolls of a 1156 x 2 px window would share a ~820^2 px lattice, 36x the 8 windows' pixels
    # (> SHARED_LATTICE_SLACK): each view has its own, its window and a few pixels' margin
    assert len(seen) == len(poses) and all(len(g.views) == 1 for g in seen)
    for g in seen:
        (u0, v0, u1, v1), = g.win
        assert u1 - u0 + 1 > 1000 and g.lat[2] <= u1 - u0 + 5 and g.lat[3] <= v1 - v0 + 5
    exact = cast_views(vol, poses, cam, poi, 0.2, share_rolls=False)
    assert np.array_equal(shared.counts, exact.counts) and np.allclose(shared.terms, exact.terms)
    assert shared.terms[:, 0].min() > 0  # every view sees the unknown cube
