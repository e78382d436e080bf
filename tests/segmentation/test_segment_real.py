"""Segmentation with colour on real fused scenes (../shared/data): the 7-Scenes kitchen table (frames 0-59,
every 3rd, fused inside a box around the table) with its white mug, and rgbd-tabletop-box."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli

# The mug on the 7-Scenes kitchen table (world metres, the data set's frame). Found once by eye: frame 30's
# colour image shows one white mug near the table's back-left corner; fusing frames 0:60:3 at 8 mm in the
# box below and segmenting gave exactly one compact segment (260 points, 4.6 cm above the table, 15 x 11 x 8
# cm box with its handle) there, whitish in colors.png.
MUG_CENTER = np.array([-0.72, -0.16, 1.95])
TABLE_BOX = ("-1.05,-0.45,1.3", "1.1,0.6,1.0")  # --origin, --size around the table (it fills the grid)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


@pytest.fixture(scope="module")
def kitchen_table(tmp_path_factory):
    from conftest import shared_path

    root = shared_path("rgbd-7scenes-redkitchen")
    tmp = tmp_path_factory.mktemp("kitchen_table")
    res = run("import", root, "-o", tmp / "k.mcap", "--frames", "0:60:3", "-q")
    assert res.exit_code == 0, res.output
    res = run("fuse", tmp / "k.mcap", "-o", tmp / "f", "--voxel-size", "0.008", "--origin=" + TABLE_BOX[0],
              "--size", TABLE_BOX[1], "--quiet")
    assert res.exit_code == 0, res.output
    return tmp


def _segment(volume, **params):
    from kinfu_cli.segmentation.pipeline import SegmentOptions, segment_volume
    from kinfu_cli.segmentation.segments import SegmentationParams

    res = segment_volume(volume, SegmentOptions(superquadrics=False, segmentation=SegmentationParams(**params)))
    return res.to_json(), res.segmentation


@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize("method", ["lccp"])  # flood fill (T_ff 0.5) joins the mug to a 1 m segment here
def test_kitchen_table_mug_is_one_segment(kitchen_table, method):
    """The table is the support plane (normal within 5 deg of the fused volume's up), the mug is one segment
    holding >= 90 % of the object points around it, and that segment does not reach into the table."""
    doc, seg = _segment(kitchen_table / "f" / "volume.npz", method=method)
    report = json.loads((kitchen_table / "f" / "report.json").read_text())
    assert doc["support_plane"] is not None and doc["up_source"] == "volume" and doc["stats"]["colors"]
    assert angle_deg(doc["support_plane"][:3], report["up"]) < 5
    plane = np.asarray(doc["support_plane"])
    assert abs(MUG_CENTER @ plane[:3] + plane[3] - 0.05) < 0.03  # the mug stands on this plane
    pts, lab = seg.points, seg.labels
    near = np.linalg.norm(pts - MUG_CENTER, axis=1) < 0.06
    h = pts @ plane[:3] + plane[3]
    mug_pts = near & (h > 0.015) & (lab > 0)
    assert mug_pts.sum() > 80
    ids, counts = np.unique(lab[mug_pts], return_counts=True)
    mug = ids[np.argmax(counts)]
    assert counts.max() >= 0.9 * mug_pts.sum(), dict(zip(ids.tolist(), counts.tolist()))
    seg = next(s for s in doc["segments"] if s["id"] == mug)
    # no segment spans mug and table: the mug's segment is mug-sized and stands above the table
    assert max(seg["oriented_box"]["extents"]) < 0.2 and seg["point_count"] < 600
    assert np.percentile(h[lab == mug], 5) > -0.01  # its foot reaches the table top (the plane's 1 cm), not beyond
    far = np.linalg.norm(pts[lab == mug] - MUG_CENTER, axis=1)
    assert np.percentile(far, 95) < 0.1  # and does not run out along it


# rgbd-tabletop-box, by eye (frames 15 and 113): a cardboard box on its side on a white desk, a glue bottle,
# a green toy, a ball, a book and card packs inside it, a cracker box and a paper stack beside it: about 8
# objects. Segments of >= 100 points count as objects (smaller ones are fragments of the box's rim).
BOX_SCENE_OBJECTS = 8


@pytest.fixture(scope="module")
def tabletop_box(tmp_path_factory):
    from conftest import shared_path

    root = shared_path("rgbd-tabletop-box")
    tmp = tmp_path_factory.mktemp("tabletop_box")
    res = run("import", root, "-o", tmp / "b.mcap", "-q")
    assert res.exit_code == 0, res.output
    res = run("fuse", tmp / "b.mcap", "-o", tmp / "f", "--voxel-size", "0.008", "--size", "1.5", "--quiet")
    assert res.exit_code == 0, res.output
    return tmp


@pytest.mark.slow
@pytest.mark.shared_data
@pytest.mark.parametrize("method", ["lccp", "flood-fill"])
def test_tabletop_box_plane_and_object_count(tabletop_box, method):
    """The desk is the support plane (within 5 deg of the fused volume's up, which is not z here) and the
    count of object-sized segments is within 50 % of the objects seen by eye (Flood Fill 5), and with LCCP the
    count of all segments is within 30 % (9 at 8 mm, all of >= 100 points)."""
    doc, seg = _segment(tabletop_box / "f" / "volume.npz", method=method)
    report = json.loads((tabletop_box / "f" / "report.json").read_text())
    assert doc["support_plane"] is not None and doc["up_source"] == "volume" and doc["stats"]["colors"]
    assert angle_deg(doc["support_plane"][:3], report["up"]) < 5 and abs(report["up"][2]) > 0.2
    big = [s for s in doc["segments"] if s["kind"] == "object" and s["point_count"] >= 100]
    print(f"tabletop-box {method}: {len(big)} segments >= 100 points, {doc['stats']['segments']} in all")
    assert 0.5 * BOX_SCENE_OBJECTS <= len(big) <= 1.5 * BOX_SCENE_OBJECTS
    if method == "lccp":  # issue 12: every segment counts, within 30 % (9 of 9 at 8 mm since the colour fill and
        # the fragment merge; 14 before, of which 10 of >= 100 points)
        assert 0.7 * BOX_SCENE_OBJECTS <= doc["stats"]["segments"] <= 1.3 * BOX_SCENE_OBJECTS


@pytest.mark.slow
@pytest.mark.shared_data
def test_kitchen_single_frame_objects_are_the_mug_and_the_brochures(tmp_path):
    """Frame 30 alone, fused into kinfu fuse's automatic grid (all the view sees: counters, chairs, floor, wall):
    on the table stand the white mug and a stack of brochures (by eye, frame 30's colour image; a flat magazine
    joins the table). Those two are the object segments; the chairs, the counters and what stands on them are
    background (session 25: 17 segments in all, each an "object" before)."""
    from conftest import shared_path

    root = shared_path("rgbd-7scenes-redkitchen")
    assert run("import", root, "-o", tmp_path / "k.mcap", "--frames", "30:31", "-q").exit_code == 0
    res = run("fuse", tmp_path / "k.mcap", "-o", tmp_path / "f", "--quiet")
    assert res.exit_code == 0, res.output
    res = run("segment", tmp_path / "f", "-o", tmp_path / "s", "--no-superquadrics", "--quiet")
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "s" / "segments.json").read_text())
    objects = [s for s in doc["segments"] if s["kind"] == "object"]
    background = [s for s in doc["segments"] if s["kind"] == "background"]
    assert len(objects) == 2 and len(background) >= 5
    dist = sorted(float(np.linalg.norm(np.asarray(s["centroid"]) - MUG_CENTER)) for s in objects)
    assert dist[0] < 0.04 < 0.15 < dist[1] < 0.5  # the mug, and the brochures a hand's width or two from it
    plane = np.asarray(doc["support_plane"])
    for s in objects:  # both stand on the table, low
        assert 0 < float(np.asarray(s["centroid"]) @ plane[:3] + plane[3]) < 0.1
