"""S(POI) counts (unknown, all, ForgetAround) walk only the sphere's voxels: the same answers as a dense distance
array over the sphere's box, without allocating one."""

import json
import tracemalloc

import numpy as np

import kinfu_cli.nbv.ranking as ranking
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.grid import EMPTY, UNKNOWN, TernaryGrid, save_ternary
from kinfu_cli.nbv.ranking import forget_around, sphere_counts, unknown_in_sphere, voxels_in_sphere
from kinfu_cli.nbv.viewpoints import SphereSpec
from kinfu_cli.nbv.workflow import NbvOptions, rank_poi_views


def _dense_mask(grid, center, radius):
    """The former implementation: a float64 d2 array over the sphere's clipped box (the reference)."""
    c = np.asarray(center, dtype=np.float64).reshape(3)
    vs = grid.voxel_size
    lo = np.maximum(np.floor((c - radius - grid.origin) / vs).astype(int), 0)
    hi = np.minimum(np.ceil((c + radius - grid.origin) / vs).astype(int) + 1, np.array(grid.shape))
    mask = np.zeros(grid.shape, dtype=bool)
    if np.any(hi <= lo):
        return mask
    ax = [grid.origin[a] + (np.arange(lo[a], hi[a]) + 0.5) * vs - c[a] for a in range(3)]
    d2 = ax[0][:, None, None] ** 2 + ax[1][None, :, None] ** 2 + ax[2][None, None, :] ** 2
    mask[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = d2 <= radius * radius
    return mask


def test_counts_and_forget_match_a_dense_distance_array():
    rng = np.random.default_rng(19)
    for trial in range(400):
        shape = tuple(int(n) for n in rng.integers(1, 24, 3))
        vs = float(rng.choice([0.01, 0.005859375, 1 / 3, 0.1]))
        origin = rng.normal(0, 1, 3) * float(rng.choice([0, 0.1, 10]))
        extent = np.array(shape) * vs
        center = origin + rng.uniform(-0.5, 1.5, 3) * extent  # partly or wholly outside too
        if trial % 4 == 0:  # on voxel centres and faces: ties with d2 == r2
            center = origin + (rng.integers(-3, 26, 3) + rng.choice([0.0, 0.5], 3)) * vs
        radius = float(rng.choice([vs * rng.uniform(0, 2), vs * int(rng.integers(1, 12)),
                                   vs * np.sqrt(int(rng.integers(1, 40))), rng.uniform(0, 1) * extent.max(),
                                   1e3, 1e-9]))
        labels = rng.integers(-1, 2, shape).astype(np.int8)
        grid = TernaryGrid(labels.copy(), origin, vs)
        mask = _dense_mask(grid, center, radius)
        want = (int(np.count_nonzero(mask & (labels == UNKNOWN))), int(np.count_nonzero(mask)))
        assert sphere_counts(grid, center, radius) == want, trial
        assert (unknown_in_sphere(grid, center, radius), voxels_in_sphere(grid, center, radius)) == want
        assert forget_around(grid, center, radius) == int(np.count_nonzero(mask & (labels != UNKNOWN)))
        expected = labels.copy()
        expected[mask] = UNKNOWN
        assert np.array_equal(grid.labels, expected), trial


def test_a_sphere_over_the_whole_grid_allocates_no_distance_array():
    """A radius past the grid (kinfu nbv --poi-radius 50) made a float64 array of the whole grid, three times."""
    labels = np.random.default_rng(0).integers(-1, 2, (96, 96, 96), dtype=np.int8)
    grid = TernaryGrid(labels, np.zeros(3), 0.01)
    sphere_counts(grid, (0.5, 0.5, 0.5), 0.01)  # numba's dispatch, before measuring
    tracemalloc.start()
    try:
        unknown, total = sphere_counts(grid, (0.48, 0.48, 0.48), 50.0)
        changed = forget_around(grid, (0.48, 0.48, 0.48), 50.0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert total == labels.size and unknown + changed == labels.size
    assert np.all(grid.labels == UNKNOWN)
    assert peak < labels.size  # the grid's own int8 size; the dense d2 array alone was 8x that


def test_rank_poi_views_walks_each_s_poi_once_for_both_counts(tmp_path, monkeypatch):
    """S(POI)'s voxel count, and the unknown count the unreachable / few-valid-views checks need, come from one
    walk per POI (they were three walks, each with its own dense array), ForgetAround being the only other."""
    labels = np.full((40, 40, 40), EMPTY, np.int8)
    labels[:, :, 25:] = UNKNOWN
    vol, pois = tmp_path / "ternary.npz", tmp_path / "pois.json"
    save_ternary(vol, TernaryGrid(labels, np.zeros(3), 0.02))
    pois.write_text(json.dumps({"pois": [{"id": 0, "position": [0.4, 0.4, 0.5], "radius": 0.1},
                                         {"id": 1, "position": [0.5, 0.4, 0.5], "radius": 0.1}]}))
    walks = {"counts": 0, "forget": 0}
    counts, forget = ranking._sphere_counts, ranking._sphere_forget

    def counting(*args):
        walks["counts"] += 1
        return counts(*args)

    def forgetting(*args):
        walks["forget"] += 1
        return forget(*args)

    monkeypatch.setattr(ranking, "_sphere_counts", counting)
    monkeypatch.setattr(ranking, "_sphere_forget", forgetting)
    cam = CameraModel(30.0, 30.0, 19.5, 14.5, 40, 30, min_range=0.3, max_range=3.0)
    sphere = SphereSpec(lon_step=90, lat_step=45, roll_step=180)
    for clear in (False, True):
        walks.update(counts=0, forget=0)
        res = rank_poi_views(vol, pois, cam, NbvOptions(sphere=sphere, table_z=None, clear=clear))
        assert walks == {"counts": 2, "forget": 2 if clear else 0}
        assert [p["sphere_voxels"] for p in res.to_json()["pois"]] == [
            int(np.count_nonzero(_dense_mask(res.grid, c, 0.1))) for c in ((0.4, 0.4, 0.5), (0.5, 0.4, 0.5))]
