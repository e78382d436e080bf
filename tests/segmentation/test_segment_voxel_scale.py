"""The volume-dependent segmentation defaults follow a coarse volume's voxel (pipeline.scale_for_voxel): a tabletop
fused at 2 cm voxels has its objects found, an explicit option still wins, fine voxels change nothing."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid
from kinfu_cli.evaluation.segment_eval import fuse_segmentation_scene, score_labelled_points
from kinfu_cli.io.labelled_cloud import LabelledCloud
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume, scale_for_voxel
from kinfu_cli.segmentation.segments import SegmentationParams
from kinfu_cli.sim.scene import scene_label_cloud


@pytest.fixture(scope="module")
def coarse():
    """Tuning scene 0 of the objects layout (8 objects) fused at 2 cm voxels (55 per 1.1 m; 12 frames, ~0.3 s)."""
    vols, scene = fuse_segmentation_scene(0, resolution=55, size=1.1, frames=12, layout="objects", colors=("mode",))
    return vols["mode"], scene


def _objects_found(vol, scene, options):
    seg = analyse_volume(vol, options).segmentation
    doc, *_ = score_labelled_points(seg.points, seg.labels, LabelledCloud(*scene_label_cloud(scene)))
    return doc["objects_found"], doc["objects_total"], seg.stats["scaled_for_voxel"]


def test_coarse_volume_finds_its_objects_with_scaled_defaults(coarse):
    vol, scene = coarse
    assert vol.voxel_size == pytest.approx(0.02)
    opts = SegmentOptions(superquadrics=False)
    found, total, scaled = _objects_found(vol, scene, opts)
    assert total == len(scene.present_objects) == 8
    assert found >= 5, (found, scaled)  # 7 when measured
    assert scaled["adjacency_radius"] >= np.sqrt(3) * vol.voxel_size  # a voxel's diagonal neighbours touch
    assert scaled["min_segment_points"] < SegmentationParams().min_segment_points
    # the tuned-for-fine defaults: surface points 2 cm apart never join, no object is found
    assert _objects_found(vol, scene, replace(opts, scale_to_voxel=False))[0] == 0


def test_explicit_values_are_kept(coarse):
    vol, _ = coarse
    given = SegmentOptions(segmentation=SegmentationParams(adjacency_radius=0.025))
    assert scale_for_voxel(given, vol.voxel_size)[0].segmentation.adjacency_radius == 0.025
    named = SegmentOptions(explicit=("adjacency_radius", "min_segment_points"))
    out, changed = scale_for_voxel(named, vol.voxel_size)
    assert set(changed) == {"fragment_points"}
    assert out.segmentation.adjacency_radius == SegmentationParams().adjacency_radius


@pytest.mark.parametrize("voxel", [0.002, 0.005, 0.006875, 0.007])
def test_fine_voxels_change_nothing(voxel):
    opts = SegmentOptions()
    out, changed = scale_for_voxel(opts, voxel)
    assert changed == {} and out is opts


def test_command_keeps_a_given_adjacency_radius(coarse, tmp_path):
    vol, _ = coarse
    vol.save(tmp_path / "volume.npz")
    docs = {}
    for name, extra in {"auto": [], "given": ["--adjacency-radius", "0.018"]}.items():
        out = tmp_path / name
        res = CliRunner().invoke(cli, ["segment", str(tmp_path / "volume.npz"), "-o", str(out), "--quiet",
                                       "--no-superquadrics", *extra])
        assert res.exit_code == 0, res.output
        docs[name] = json.loads((out / "segments.json").read_text())
    assert docs["auto"]["stats"]["scaled_for_voxel"]["adjacency_radius"] == pytest.approx(0.04)
    assert "adjacency_radius" not in docs["given"]["stats"]["scaled_for_voxel"]
    assert docs["given"]["options"]["segmentation"]["adjacency_radius"] == 0.018
    objects = {k: sum(s["kind"] == "object" for s in d["segments"]) for k, d in docs.items()}
    assert objects["auto"] > objects["given"], objects


def _box_on_table(voxel: float) -> TernaryGrid:
    """Labels only: a 0.8 m table slab and a 12 cm cube on it (occupied shells, unknown inside, empty around)."""
    n = int(round(0.8 / voxel))
    lab = np.full((n, n, n // 2), EMPTY, np.int8)
    top = n // 8
    lab[:, :, :top] = UNKNOWN
    lab[:, :, top] = OCCUPIED
    b = int(round(0.12 / voxel))
    lo = (n - b) // 2
    lab[lo:lo + b, lo:lo + b, top + 1:top + 1 + b] = OCCUPIED
    lab[lo + 1:lo + b - 1, lo + 1:lo + b - 1, top + 1:top + b] = UNKNOWN
    return TernaryGrid(lab, np.zeros(3), voxel)


@pytest.mark.parametrize("voxel", [0.02, 0.03])
def test_a_box_on_a_coarse_labels_grid_is_one_segment(voxel):
    opts = SegmentOptions(superquadrics=False)
    seg = analyse_volume(_box_on_table(voxel), opts).segmentation
    assert set(np.unique(seg.labels).tolist()) - {-1, 0} == {1}  # the box, one segment, on its support
    assert seg.plane is not None and abs(seg.plane[2]) > 0.99
    old = analyse_volume(_box_on_table(voxel), replace(opts, scale_to_voxel=False)).segmentation
    assert set(np.unique(old.labels).tolist()) - {-1, 0} == set()  # the unscaled defaults found nothing


def test_voxels_coarser_than_2_cm_are_a_warning(coarse):
    """At 5 cm the sample tabletop gave 2 of its 4 objects and said nothing; from 2 cm on, scaling cannot help
    objects a few voxels across: the result says so. At 2 cm (objects recall 0.84) it does not."""
    opts = SegmentOptions(superquadrics=False)
    assert not any("coarser than" in w for w in analyse_volume(coarse[0], opts).warnings)
    res = analyse_volume(_box_on_table(0.03), opts)
    (warning,) = [w for w in res.warnings if "coarser than" in w]
    assert "30 mm" in warning and "15 cm" in warning


def test_a_voxel_too_coarse_for_any_neighbourhood_is_an_error_naming_the_file_not_an_option(tmp_path):
    """A 1000 m voxel (a damaged or foreign file) scaled the adjacency radius to 2000 m, and the error then blamed
    --adjacency-radius, an option nobody gave; it now names the file and its voxel size."""
    from kinfu_cli.core.grid import save_ternary

    grid = _box_on_table(0.02)
    path = tmp_path / "huge.npz"
    save_ternary(path, TernaryGrid(grid.labels, grid.origin, 1000.0))
    res = CliRunner().invoke(cli, ["segment", str(path), "-o", str(tmp_path / "seg"), "--quiet"])
    assert res.exit_code == 2
    assert f"{path}: voxel size 1000 m is too coarse to segment" in res.output
    assert "--adjacency-radius" not in res.output and not (tmp_path / "seg").exists()
    given = CliRunner().invoke(cli, ["segment", str(path), "-o", str(tmp_path / "seg"), "--quiet",
                                     "--adjacency-radius", "0.02"])
    assert "too coarse" not in given.output  # the caller's own radius is theirs: no scaling, no such error
