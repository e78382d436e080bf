"""Files a command reads beside its named input (segments.ply beside segments.json, a fusion's report.json and
trajectory.tum beside its volume, a ROS 2 bag's folder beside its .db3) are inputs too: never written over, even
with --force."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.core.ownership import mark_folder_output, record_tree
from kinfu_cli.io.labelled_cloud import write_labelled_cloud
from kinfu_cli.segmentation.outputs import segment_colors

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_data" / "tabletop"
# a tetrahedron, centred (localize's MODEL)
V = np.array([[0, 0, 0], [0.2, 0, 0], [0.05, 0.12, 0], [0.03, 0.04, 0.09]], dtype=float)
F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]])


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def unchanged(paths: list[Path]):
    """The bytes of `paths` now; call the result to assert they are still the same."""
    before = {p: p.read_bytes() for p in paths}
    return lambda: all(p.read_bytes() == b for p, b in before.items())


@pytest.fixture
def segment_output(tmp_path):
    """A segment output folder as `kinfu segment` writes it, then moved: segments.ply (segment colours) and
    segments.json, object 1 on the faces of the tetrahedron model.ply; and ground-truth labels with their names."""
    import open3d as o3d

    v = V - V.mean(0)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(F))
    o3d.io.write_triangle_mesh(str(tmp_path / "model.ply"), mesh)
    w = np.random.default_rng(0).dirichlet(np.ones(3), 40)  # points on the faces, in turn
    pts = np.einsum("nk,nkd->nd", w, v[F[np.arange(40) % len(F)]])
    labels = np.ones(len(pts), dtype=np.int64)
    seg = tmp_path / "seg"
    seg.mkdir()
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    cloud.colors = o3d.utility.Vector3dVector(segment_colors(labels))
    o3d.io.write_point_cloud(str(seg / "segments.ply"), cloud)
    (seg / "segments.json").write_text(json.dumps({"segments": [{"id": 1, "kind": "object",
                                                                  "point_count": len(pts)}]}))
    record_tree(seg)  # kinfu's, moved here (no manifest above lists it): kinfu may replace its files, not inputs
    mark_folder_output(seg)
    gt = tmp_path / "gt"
    gt.mkdir()
    write_labelled_cloud(gt / "labels.ply", pts, labels)
    (gt / "changes.json").write_text(json.dumps({"labels": {"1": "tetra"}}))
    return tmp_path / "model.ply", seg, gt


@pytest.mark.parametrize("force", [[], ["--force"]], ids=["", "force"])
def test_localize_never_writes_over_the_segments_ply_it_reads(segment_output, force):
    model, seg, _ = segment_output
    same = unchanged([seg / "segments.ply", seg / "segments.json"])
    res = run("localize", model, "--segments", seg / "segments.json", "--segment", 1, "-o", seg / "segments.ply",
              "--particles", 30, "--quiet", *force)
    one_line_error(res, "--output", "segments.ply", "is also an input")
    assert same()


@pytest.mark.parametrize("named, output", [("segments.ply", "segments.json"), ("segments.json", "segments.ply")])
def test_eval_segment_never_writes_over_the_segment_file_beside_the_one_named(segment_output, named, output):
    _, seg, gt = segment_output
    same = unchanged([seg / "segments.ply", seg / "segments.json"])
    res = run("eval", "segment", seg / named, "--ground-truth", gt / "labels.ply", "-o", seg / output, "--quiet",
              "--force")
    one_line_error(res, "--output", output, "is also an input")
    assert same()
    # scoring the same files elsewhere works: the refusal is about the path only
    assert run("eval", "segment", seg / named, "--ground-truth", gt / "labels.ply", "-o", seg.parent / "e.json",
               "--quiet").exit_code == 0


def test_eval_segment_never_writes_over_the_label_names_beside_the_labels_file(segment_output):
    _, seg, gt = segment_output
    same = unchanged([gt / "changes.json"])
    res = run("eval", "segment", seg, "--ground-truth", gt / "labels.ply", "--plot", gt / "changes.json",
              "--quiet", "--force")
    one_line_error(res, "--plot", "changes.json", "is also an input")
    assert same()


def test_eval_fusion_never_writes_over_the_report_beside_a_mesh(tmp_path):
    fused = tmp_path / "fused"
    fused.mkdir()
    (fused / "mesh.ply").write_bytes(b"a mesh")
    (fused / "report.json").write_text('{"frames": {"start_s": 1.0}}')
    same = unchanged([fused / "report.json"])
    res = run("eval", "fusion", fused / "mesh.ply", "--ground-truth", SAMPLE / "ground_truth", "-o",
              fused / "report.json", "--force")
    one_line_error(res, "--output", "report.json", "is also an input")
    assert same()


@pytest.mark.parametrize("command", ["poi", "export", "fuse"])
def test_a_ros2_bag_named_by_its_db3_keeps_its_metadata(tmp_path, command):
    """The reader reads the bag's folder (metadata.yaml lists its .db3 files)."""
    bag = tmp_path / "bag"
    shutil.copytree(SAMPLE / "recording_ros2", bag)
    db3 = next(bag.glob("*.db3"))
    same = unchanged([bag / "metadata.yaml"])
    options = {"poi": ["--algorithm", "zvc", "-o"], "export": ["--trajectory", "tum", "-o"],
               "fuse": ["-o", tmp_path / "fused", "--quiet", "--viz"]}[command]
    res = run(command, db3, *options, bag / "metadata.yaml", "--force")
    one_line_error(res, "metadata.yaml", "a file of the input folder")
    assert same()
