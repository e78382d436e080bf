"""`kinfu nbv` on doubtful input: the clearance ball, lenient pois.json files, and viewing spheres too large to make.

Before: `--clearance` looked at 27 points at +-C around the sensor and ignored those outside the grid, so an occupied
voxel between them passed and the valid views of a POI went 96, 0, 32, 96 for C = 0, 0.3, 2, 3 m; pois.json took
`"radius": true` as 1 m, a radius of 1e6 m, id 1.7 as 1, repeated ids, positions as strings and a NaN Gaussian; and
`--lon-step 0.01` built 2.9 million poses per POI (1.7 GB) before ranking any.
"""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import one_line_error
from kinfu_cli.cli import cli
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid, save_ternary
from kinfu_cli.core.pois import PoiFileError, read_pois
from kinfu_cli.nbv.ranking import reject_reasons
from kinfu_cli.nbv.raycast import RayVolume
from kinfu_cli.nbv.viewpoints import MAX_SPHERE_VIEWS, SphereSpec, sphere_view_count, sphere_viewpoints

VS = 0.05


def _poses(points) -> np.ndarray:
    T = np.tile(np.eye(4), (len(points), 1, 1))
    T[:, :3, 3] = points
    return T


def _random_grid(seed: int, n: int = 12) -> TernaryGrid:
    rng = np.random.default_rng(seed)
    lab = rng.choice(np.array([EMPTY] * 6 + [UNKNOWN, OCCUPIED], np.int8), size=(n, n, n))
    return TernaryGrid(lab, np.array([0.1, -0.2, 0.0]), VS)


def _brute_reasons(grid: TernaryGrid, points, clearance: float) -> list:
    """The ball by definition: the sensor's own voxel or any voxel centre within `clearance`, on the grid padded with
    enough never observed (unknown) space."""
    pad = int(np.ceil(clearance / VS)) + 6  # the points lie up to 4 voxels outside
    lab = np.pad(grid.labels, pad, constant_values=UNKNOWN)
    inside = np.pad(np.ones(grid.shape, bool), pad, constant_values=False)
    centres = grid.origin + (np.indices(lab.shape).reshape(3, -1).T - pad + 0.5) * VS
    out = []
    for p in points:
        own = tuple(np.floor((p - grid.origin) / VS).astype(int) + pad)
        ball = np.linalg.norm(centres - p, axis=1) <= clearance
        ball[np.ravel_multi_index(own, lab.shape)] = True
        labs, ins = lab.ravel()[ball], inside.ravel()[ball]
        out.append("inside_occupied" if np.any((labs == OCCUPIED) & ins) else
                   "inside_unknown" if np.any(labs == UNKNOWN) else None)
    return out


def test_a_view_next_to_an_occupied_voxel_is_rejected_whatever_the_clearance():
    lab = np.full((20, 20, 20), EMPTY, np.int8)
    lab[10, 10, 10] = OCCUPIED  # centre (0.525, 0.525, 0.525)
    vol = RayVolume.from_grid(TernaryGrid(lab, np.zeros(3), VS))
    sensor = _poses([[0.425, 0.525, 0.525]])  # 0.1 m from the voxel's centre, the old samples at +-0.3 m missed it
    for c in (0.1, 0.3, 0.45):
        assert reject_reasons(vol, sensor, clearance=c) == ["inside_occupied"], c
    assert reject_reasons(vol, sensor, clearance=0.09) == [None]


@pytest.mark.parametrize("seed", [0, 1])
def test_the_clearance_ball_is_exact_and_the_valid_count_never_grows_with_it(seed):
    grid = _random_grid(seed)
    vol = RayVolume.from_grid(grid)
    rng = np.random.default_rng(seed + 10)
    points = grid.origin + rng.uniform(-0.2, 0.8, (60, 3))  # inside the 0.6 m grid and around it
    valid = []
    for c in (0.0, 0.02, 0.05, 0.08, 0.15, 0.3, 0.7, 2.0, 5.0):
        reasons = reject_reasons(vol, _poses(points), clearance=c)
        if 0 < c <= 0.3:
            assert reasons == _brute_reasons(grid, points, c), c
        valid.append(sum(r is None for r in reasons))
    assert valid[0] > 0
    assert all(a >= b for a, b in zip(valid, valid[1:])), valid
    assert valid[-1] == 0


def test_with_a_clearance_space_outside_the_volume_counts_as_unknown():
    lab = np.full((10, 10, 10), EMPTY, np.int8)
    vol = RayVolume.from_grid(TernaryGrid(lab, np.zeros(3), VS))
    T = _poses([[0.275, 0.275, 0.275], [0.275, 0.275, 0.48], [0.275, 0.275, 0.7]])  # middle, 2 cm below the top, above
    assert reject_reasons(vol, T) == [None, None, None]  # no clearance: positions outside are allowed
    assert reject_reasons(vol, T, clearance=0.01) == [None, None, "inside_unknown"]
    assert reject_reasons(vol, T, clearance=0.05) == [None, "inside_unknown", "inside_unknown"]
    assert reject_reasons(vol, T, clearance=0.05, reject_unknown=False) == [None, None, None]


POI = {"id": 0, "position": [0.37, 0.1, 0.88]}


@pytest.mark.parametrize("change, field", [
    ({"radius": True}, "pois[0].radius is True"),
    ({"radius": 1e6}, "pois[0].radius is 1000000.0"),
    ({"id": 1.7}, "pois[0].id is 1.7, expected an integer"),
    ({"id": "3"}, "pois[0].id is '3', expected an integer"),
    ({"position": ["0.37", "0.1", "0.88"]}, "pois[0].position is ['0.37', '0.1', '0.88'], expected [x, y, z]"),
    ({"position": [1e308, 0, 0]}, "pois[0].position is [1e+308, 0, 0]"),
    ({"time": "1.5"}, "pois[0].time is '1.5', expected a number"),
    ({"gaussian": {"mean": [float("nan"), 0, 0, 0], "covariance": np.zeros((4, 4)).tolist(), "weight": 0.5}},
     "pois[0].gaussian needs mean [4], covariance 4x4 (finite numbers)"),
    ({"gaussian": {"mean": [0, 0, 0, 0], "covariance": np.eye(4).tolist(), "weight": float("nan")}},
     "pois[0].gaussian"),
])
def test_a_malformed_poi_is_refused_naming_the_file_and_field(tmp_path, change, field):
    path = tmp_path / "pois.json"
    path.write_text(json.dumps({"pois": [{**POI, **change}]}))
    with pytest.raises(PoiFileError) as err:
        read_pois(path)
    assert str(err.value).startswith(f"{path}: {field}")


def test_repeated_poi_ids_are_refused(tmp_path):
    path = tmp_path / "pois.json"
    path.write_text(json.dumps({"pois": [POI, {"id": 2, "position": [0, 0, 1]}, {**POI, "position": [0.3, 0, 1]}]}))
    with pytest.raises(PoiFileError, match=r"pois\[2\]\.id 0 repeats pois\[0\]\.id"):
        read_pois(path)


def test_well_formed_pois_still_read(tmp_path):
    path = tmp_path / "pois.json"
    g = {"mean": [0.37, 0.1, 0.88, 1.3], "covariance": (np.eye(4) * 1e-4).tolist(), "weight": 0.2}
    path.write_text(json.dumps({"pois": [{**POI, "radius": 100, "time": 1.5, "gaussian": g},
                                         {"id": 3.0, "position": [0, 0, 1], "gaussian": None}]}))
    a, b = read_pois(path)
    assert (a.id, a.radius, a.gaussian.weight) == (0, 100.0, 0.2)
    assert b.id == 3 and isinstance(b.id, int) and b.radius == 0.2 and np.isnan(b.time)


def test_the_viewing_sphere_is_counted_and_bounded_before_it_is_made():
    assert sphere_view_count() == 960 == len(SphereSpec().viewpoints((0, 0, 0)))
    assert sphere_view_count(lon_step=1, lat_step=45, roll_step=90) == len(
        sphere_viewpoints((0, 0, 0), lon_step=1, lat_step=45, roll_step=90))
    with pytest.raises(ConfigError) as err:
        sphere_viewpoints((0, 0, 0), lon_step=1e-9)  # 3.6e11 longitudes: making them would never end
    assert err.value.parameter == "lon_step/lat_step/roll_step"
    assert "more than the 100,000 allowed" in str(err.value) and MAX_SPHERE_VIEWS == 100_000


def _volume_and_pois(tmp_path, poi: dict):
    lab = np.full((20, 20, 20), EMPTY, np.int8)
    lab[:, :, :4] = OCCUPIED
    vol, pois = tmp_path / "ternary.npz", tmp_path / "pois.json"
    save_ternary(vol, TernaryGrid(lab, np.zeros(3), VS))
    pois.write_text(json.dumps({"pois": [poi]}))
    return vol, pois


def test_nbv_refuses_a_sphere_step_that_would_make_millions_of_views(tmp_path):
    vol, pois = _volume_and_pois(tmp_path, {"id": 0, "position": [0.5, 0.5, 0.4]})
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--lon-step", "0.01", "--quiet"])
    one_line_error(res, "--lon-step/--lat-step/--roll-step", "2,880,000 candidate views", "100,000")


def test_nbv_refuses_a_boolean_radius_in_one_line(tmp_path):
    vol, pois = _volume_and_pois(tmp_path, {"id": 0, "position": [0.5, 0.5, 0.4], "radius": True})
    res = CliRunner().invoke(cli, ["nbv", str(vol), "--pois", str(pois), "--quiet"])
    one_line_error(res, str(pois), "pois[0].radius is True")
