"""Change regions between two ternary grids: removed / added objects found where they were, pose noise and
unobserved space never reported as changes, grids with different placements compared on their common box."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from kinfu_cli.change.diff import ChangeParams, diff_grids
from kinfu_cli.change.regions import components, empty_all_around
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.core.pois import Poi
from kinfu_cli.evaluation.changes import score_change_pois

VS = 0.01
SHAPE = (60, 50, 40)
TABLE_K = 10  # the table top's first voxel layer


def scene(objects: list[tuple[int, int, int, int, int, int]], shift: int = 0) -> np.ndarray:
    """Labels as a fusion from above sees a table (occupied band of 3 voxels, unknown below) and boxes on it
    (occupied band 2 voxels deep inside each face, unknown core), free space above; `shift` moves it all in x."""
    lab = np.zeros(SHAPE, dtype=np.int8)
    lab[:, :, TABLE_K + 3:] = -1
    lab[:, :, TABLE_K:TABLE_K + 3] = 1
    for x0, y0, z0, x1, y1, z1 in objects:
        lab[x0:x1, y0:y1, z0:z1] = 1
        lab[x0 + 2:x1 - 2, y0 + 2:y1 - 2, z0 + 2:z1 - 2] = 0
    if shift:
        lab = np.roll(lab, shift, axis=0)
    return lab


OBJ_A = (10, 10, TABLE_K + 3, 18, 18, TABLE_K + 11)  # an 8 cm cube on the table
OBJ_B = (40, 30, TABLE_K + 3, 48, 38, TABLE_K + 11)


def grid(labels, origin=(0.0, 0.0, 0.0), voxel_size=VS, frame="world") -> TernaryGrid:
    return TernaryGrid(labels, np.array(origin, dtype=float), voxel_size, frame)


def box_centre(obj) -> np.ndarray:
    return (np.array(obj[:3]) + np.array(obj[3:])) / 2 * VS


def test_identical_volumes_give_no_region():
    g = grid(scene([OBJ_A]))
    r = diff_grids(g, g)
    assert r.regions == [] and r.masks.raw == {"removed": 0, "added": 0} and not r.warnings
    assert r.to_json()["overlap"]["fraction"] == 1.0


def test_moved_object_is_removed_at_its_old_place_and_added_at_its_new_place():
    r = diff_grids(grid(scene([OBJ_A])), grid(scene([OBJ_B])))
    assert [x.kind for x in r.regions] == ["removed", "added"] or [x.kind for x in r.regions] == ["added", "removed"]
    by_kind = {x.kind: x for x in r.regions}
    # the whole band of the cube, less the layer touching the table (within a voxel of the after table)
    for kind, obj in (("removed", OBJ_A), ("added", OBJ_B)):
        reg = by_kind[kind]
        assert np.linalg.norm(reg.centroid[:2] - box_centre(obj)[:2]) < 1e-9  # symmetric in x, y
        assert abs(reg.centroid[2] - box_centre(obj)[2]) < 0.01
        band = (8 * 8 * 8 - 4 * 4 * 4) - 8 * 8 * 1  # the bottom layer lies against the table: pose-noise margin
        assert len(reg.points) == band and reg.volume == pytest.approx(band * VS ** 3)
        doc = reg.to_json()
        assert doc["box_min"] == pytest.approx([obj[0] * VS, obj[1] * VS, (obj[2] + 1) * VS])
        assert doc["box_max"] == pytest.approx([obj[3] * VS, obj[4] * VS, obj[5] * VS])


def test_a_one_voxel_pose_error_is_not_a_change_but_two_voxels_with_margin_zero_are():
    before = grid(scene([OBJ_A]))
    after = grid(scene([OBJ_A], shift=1))
    assert diff_grids(before, after).regions == []
    noisy = diff_grids(before, after, ChangeParams(margin=0, min_volume=0))
    assert noisy.masks.raw["removed"] > 50 and len(noisy.regions) > 0
    assert diff_grids(before, grid(scene([OBJ_A], shift=2)), ChangeParams(margin=2)).regions == []


def test_small_regions_are_dropped_and_counted():
    after = scene([])
    after[30, 30, TABLE_K + 5] = 1  # a speckle in the free space
    r = diff_grids(grid(scene([])), grid(after), ChangeParams(min_volume=0))
    assert len(r.regions) == 1 and r.regions[0].kind == "added" and len(r.regions[0].points) == 1
    r = diff_grids(grid(scene([])), grid(after))  # default: 27 voxels
    assert r.regions == [] and r.masks.dropped_regions == 1 and r.masks.dropped_voxels == 1


def test_unknown_space_is_ignored_counted_and_explained():
    before = scene([OBJ_A])
    after = scene([])
    after[5:25, 5:25, TABLE_K + 3:] = 0  # the after scan never looked where the object was
    r = diff_grids(grid(before), grid(after))
    assert r.regions == []
    assert r.masks.unknown_ignored["occupied_before_unknown_after"] == 8 * 8 * 8 - 4 * 4 * 4
    assert r.masks.hidden == {"occupied_before_unknown_after": 8 * 8 * 8 - 4 * 4 * 4 - 8 * 8,  # not the bottom
                              "occupied_after_unknown_before": 0}
    assert any("cannot be seen" in w for w in r.warnings)


def test_grids_placed_differently_are_compared_on_their_common_box():
    before = grid(scene([OBJ_A]))
    ref = diff_grids(before, grid(scene([OBJ_B])))
    lab = scene([OBJ_B])
    for shift, frac in ((np.array([7, -4, 3]), 0.0), (np.array([5, 6, -2]), 0.4)):  # whole and part voxels
        # an after grid whose origin is shift + frac voxels away; its voxel j holds the world content of the
        # before lattice's voxel shift + j (the nearest), unknown beyond the scene
        src = [np.arange(n) + s for n, s in zip(SHAPE, shift)]
        ok = [(i >= 0) & (i < n) for i, n in zip(src, SHAPE)]
        moved = np.zeros(SHAPE, dtype=np.int8)
        moved[np.ix_(*[np.flatnonzero(o) for o in ok])] = lab[np.ix_(*[i[o] for i, o in zip(src, ok)])]
        r = diff_grids(before, grid(moved, origin=(shift + frac) * VS))
        assert [(x.kind, len(x.points)) for x in r.regions] == [(x.kind, len(x.points)) for x in ref.regions]
        for x, y in zip(r.regions, ref.regions):
            assert np.allclose(x.centroid, y.centroid)
        assert r.to_json()["common_box"]["min"] == pytest.approx(np.maximum(shift, 0) * VS)
        assert r.to_json()["common_box"]["shape"] == (np.array(SHAPE) - np.abs(shift)).tolist()


def test_different_voxel_sizes_and_disjoint_grids_are_refused_naming_the_file():
    g = grid(scene([OBJ_A]))
    with pytest.raises(VolumeError, match=r"after\.npz: voxel size 0\.02 m, but before\.npz has 0\.01 m"):
        diff_grids(g, grid(scene([]), voxel_size=0.02), names=("before.npz", "after.npz"))
    with pytest.raises(VolumeError, match=r"after\.npz: its grid .* does not overlap before\.npz"):
        diff_grids(g, grid(scene([]), origin=(5.0, 0.0, 0.0)), names=("before.npz", "after.npz"))
    with pytest.raises(ConfigError, match="margin"):
        diff_grids(g, g, ChangeParams(margin=-1))


def test_frames_that_differ_and_a_small_overlap_are_warned():
    lab = scene([])
    r = diff_grids(grid(lab, frame="map"), grid(lab, origin=(0.5, 0.0, 0.0), frame="odom"))
    assert any("'map'" in w and "'odom'" in w for w in r.warnings)
    assert any("overlap little" in w for w in r.warnings)


def test_free_space_check_is_scipys_erosion_read_at_the_changed_voxels():
    rng = np.random.default_rng(3)
    lab = rng.choice(np.array([-1, -1, -1, 0, 1], dtype=np.int8), size=(20, 17, 15))
    idx = np.argwhere(np.ones(lab.shape, dtype=bool))
    for margin in (0, 1, 2):
        ref = ndimage.binary_erosion(lab == -1, structure=np.ones((3, 3, 3)), iterations=margin,
                                     border_value=0) if margin else lab == -1
        assert np.array_equal(empty_all_around(lab, idx, margin).reshape(lab.shape), ref)


def test_components_are_ndimage_labels_26_connectivity():
    rng = np.random.default_rng(4)
    mask = rng.random((25, 20, 18)) < 0.12
    lab, n = ndimage.label(mask, structure=np.ones((3, 3, 3)))
    ours = components(np.argwhere(mask))
    assert len(ours) == n
    assert sorted(len(c) for c in ours) == sorted(np.bincount(lab.ravel())[1:].tolist())
    for c in ours:
        assert len(set(lab[tuple(c.T)].tolist())) == 1


def test_pois_scored_against_regions_with_the_020_m_rule():
    r = diff_grids(grid(scene([OBJ_A])), grid(scene([OBJ_B])))
    a, b = box_centre(OBJ_A), box_centre(OBJ_B)
    pois = [Poi(0, a + [0.0, 0.0, 0.15], 1.0, 1.0),  # 0.15 m above the cube's centre: 0.11 from its top face
            Poi(1, a + [0.0, 0.23, 0.0], 2.0, 1.0),  # 0.19 m beside the face: still a true positive
            Poi(2, (a + b) / 2 + [0, 0, 0.25], 3.0, 1.0)]  # far from both
    doc = score_change_pois(r, pois)
    assert (doc["tp"], doc["fp"], doc["fn"]) == (2, 1, 1)
    assert doc["precision"] == pytest.approx(2 / 3) and doc["recall"] == pytest.approx(0.5)
    assert doc["f1"] == pytest.approx(2 * (2 / 3) * 0.5 / (2 / 3 + 0.5))
    assert [p["true_positive"] for p in doc["per_poi"]] == [True, True, False]
    assert doc["per_poi"][0]["distance_m"] == pytest.approx(np.hypot(0.15 - 0.035, 0.005 * np.sqrt(2)), abs=1e-4)
    removed = next(x.id for x in r.regions if x.kind == "removed")
    assert doc["missed_regions"] == [next(x.id for x in r.regions if x.kind == "added")]
    assert doc["per_poi"][1]["nearest_region"] == removed and r.to_json()["pois"] is doc
