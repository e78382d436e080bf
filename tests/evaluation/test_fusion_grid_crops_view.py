"""`kinfu eval fusion` on a grid that crops the scene: completeness counted only the true surface inside the grid,
so a 0.5 m corner of a synth scene scored 0.914 (the whole scene 0.772) with `warnings: []`. Now the share of the
visible true surface outside the grid is in the results (reconstruction.visible_share_outside) and, past
SEEN_OUTSIDE_WARN, a warning."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.evaluation.reconstruction import SEEN_OUTSIDE_WARN
from kinfu_cli.fusion.volume import TernaryVolume

SPACING = "0.02"  # coarser than the default (fast), and the threshold as coarse (no spacing warning)


def _truth_corner(sample_dir, out, lo, hi):
    """A `kinfu fuse`-like folder: the true after-state mesh cut to the box [lo, hi], and a (never fused) volume
    whose grid is that box."""
    mesh = o3d.io.read_triangle_mesh(str(sample_dir / "ground_truth" / "scene_after.ply"))
    v = np.asarray(mesh.vertices)
    keep = np.all((v >= lo) & (v <= hi), axis=1)
    mesh.remove_vertices_by_mask(~keep)
    out.mkdir()
    assert o3d.io.write_triangle_mesh(str(out / "mesh.ply"), mesh)
    TernaryVolume(size=tuple(np.subtract(hi, lo)), voxel_size=0.02, origin=lo).save(out / "volume.npz")
    return out


def _eval(path, sample_dir, out):
    res = CliRunner().invoke(cli, ["eval", "fusion", str(path), "--ground-truth", str(sample_dir), "--spacing",
                                   SPACING, "--threshold", SPACING, "--quiet", "-o", str(out)])
    assert res.exit_code == 0, res.output
    return res, json.loads(out.read_text())


def test_a_grid_that_crops_the_seen_surface_is_warned(sample_dir, tmp_path):
    gt = json.loads((sample_dir / "ground_truth" / "changes.json").read_text())
    x, y, z = gt["table"]["center"][0], gt["table"]["center"][1], gt["table"]["top_z"]
    lo, hi = np.array([x - 0.15, y - 0.15, z - 0.1]), np.array([x + 0.15, y + 0.15, z + 0.2])
    res, doc = _eval(_truth_corner(sample_dir, tmp_path / "corner", lo, hi), sample_dir, tmp_path / "e.json")
    r = doc["reconstruction"]
    share = r["visible_share_outside"]
    assert share > 0.5 and r["samples_visible_outside"] > r["samples_observed"]
    assert share == r["samples_visible_outside"] / (r["samples_visible_outside"] + r["samples_observed"])
    said = [w for w in doc["warnings"] if "true surface the cameras saw" in w]
    assert len(said) == 1 and "outside the volume grid" in said[0]
    assert f"{100 * share:.0f} % " in said[0] and f"only the {r['samples_observed']} inside" in said[0]
    assert f"kinfu: warning: {said[0]}" in res.output


def test_the_whole_scene_leaves_nothing_out(sample_dir, tmp_path):
    """The true mesh itself (a bare mesh: its bounding box grown by the margin) holds all it shows."""
    _, doc = _eval(sample_dir / "ground_truth" / "scene_after.ply", sample_dir, tmp_path / "e.json")
    assert doc["reconstruction"]["samples_visible_outside"] == 0
    assert doc["reconstruction"]["visible_share_outside"] == 0.0 < SEEN_OUTSIDE_WARN
    assert not [w for w in doc["warnings"] if "true surface the cameras saw" in w]


def test_surface_beyond_the_fused_depth_range_is_not_blamed_on_the_grid(sample_dir, tmp_path):
    """A fusion limited to max_depth 1.2 m (its auto grid around what it fused) was told that 83 % of the visible
    true surface lay outside its grid: the far surface was left out by the depth range, not the grid. The surface
    outside the grid now counts only within the volume's depth range."""
    gt = json.loads((sample_dir / "ground_truth" / "changes.json").read_text())
    x, y, z = gt["table"]["center"][0], gt["table"]["center"][1], gt["table"]["top_z"]
    lo, hi = np.array([x - 0.15, y - 0.15, z - 0.1]), np.array([x + 0.15, y + 0.15, z + 0.2])
    corner = _truth_corner(sample_dir, tmp_path / "corner", lo, hi)
    _, full = _eval(corner, sample_dir, tmp_path / "full.json")
    TernaryVolume(size=tuple(np.subtract(hi, lo)), voxel_size=0.02, origin=lo, min_depth=0.3,
                  max_depth=0.31).save(corner / "volume.npz")  # a depth range that reaches next to nothing
    _, near = _eval(corner, sample_dir, tmp_path / "near.json")
    assert full["reconstruction"]["samples_visible_outside"] > 0
    assert near["reconstruction"]["samples_visible_outside"] < 0.05 * full["reconstruction"]["samples_visible_outside"]
    assert not [w for w in near["warnings"] if "true surface the cameras saw" in w]
