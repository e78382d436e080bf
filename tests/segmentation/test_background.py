"""Background segments (segmentation/background.py): a single view fused into a grid as wide as what it sees
holds walls and furniture beside the table; they are background, not objects, and no object is."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial import cKDTree

from kinfu_cli.cli import cli
from kinfu_cli.core.poses import look_at
from kinfu_cli.evaluation.segments import PHOTOMETRIC
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.segmentation.background import BELOW, BEYOND
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_cloud, analyse_volume
from kinfu_cli.sim.scenario import make_scenario
from kinfu_cli.sim.scene import resting_object, scene_label_cloud
from kinfu_cli.sim.sensor import DepthSensor

W, H = 320, 240
WALLS = ("wall_back", "wall_side", "cabinet")


def _looking_at(target, azimuth: float, elevation_deg: float, distance: float) -> np.ndarray:
    """Camera pose (x right, y down, z forward) at `distance` from `target`, looking at it."""
    e = np.radians(elevation_deg)
    p = np.asarray(target) + distance * np.array([np.cos(azimuth) * np.cos(e), np.sin(azimuth) * np.cos(e), np.sin(e)])
    return look_at(p, target)


def _room_view(seed: int, azimuth: float, walls: bool = True):
    """The household scene `seed` with a wall behind and beside the table and a cabinet on the floor, one noisy
    view from 1.1 m at 30 deg elevation fused into a grid around everything it sees (as `kinfu fuse --size auto`):
    (volume, scene, its walls' ids)."""
    sc = make_scenario(seed, width=W, height=H, frames=2, noise=True, layout="household")
    scene = sc.scene_after
    t = scene.table
    extra = (resting_object("wall_back", "box", {"x": 5, "y": 0.1, "z": 2.6}, xy=(t.center[0], t.center[1] + 1.6),
                            colour=(0.85, 0.85, 0.8)),
             resting_object("wall_side", "box", {"x": 0.1, "y": 5, "z": 2.6}, xy=(t.center[0] + 1.6, t.center[1]),
                            colour=(0.8, 0.82, 0.85)),
             resting_object("cabinet", "box", {"x": 0.6, "y": 0.5, "z": 0.9}, xy=(t.center[0] + 1.0, t.center[1] + 1.0),
                            colour=(0.5, 0.35, 0.2))) if walls else ()
    scene = replace(scene, objects=scene.objects + extra)
    T = _looking_at(np.array([0.0, 0.0, 0.75]), azimuth, 30.0, 1.1)
    depth, rgb = DepthSensor(sc.K, W, H, noise=True, seed=seed, **PHOTOMETRIC).render(scene, T, frame_seed=0)
    v, u = np.nonzero(depth > 0)
    z = depth[v, u].astype(np.float64)
    K = sc.K
    pts = (T @ np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z, np.ones_like(z)]))[:3].T
    lo, hi = pts.min(axis=0) - 0.05, pts.max(axis=0) + 0.05
    res = tuple(int(np.ceil(x)) for x in (hi - lo) / 0.006)
    vol = TernaryVolume(size=tuple(np.array(res) * 0.006), resolution=res, origin=lo, color=True)
    vol.integrate(depth, K, T, rgb)
    return vol, scene


def _owners(result, scene) -> dict[int, str]:
    """Segment id -> the id of the scene part most of its points lie on ("table" for the table and floor)."""
    gp, gl = scene_label_cloud(scene)
    names = {scene.label_of(o.id): o.id for o in scene.present_objects}
    seg = result.segmentation
    d, i = cKDTree(gp).query(seg.points)
    truth = np.where(d < 0.015, gl[i], -1)
    out = {}
    for s in np.unique(seg.labels[seg.labels > 0]):
        o, c = np.unique(truth[seg.labels == s], return_counts=True)
        main_ = int(o[np.argmax(c)])
        out[int(s)] = names.get(main_, "table" if main_ == 0 else "nothing")
    return out


@pytest.mark.parametrize("azimuth", [3.1, 4.7])  # from -x and -y: the side wall, the back wall and cabinet
def test_walls_and_cabinet_are_background_and_no_object_is(azimuth):
    """Each wall and the cabinet seen is background (before: each an "object" segment, 1-2 per view on these
    scenes); every segment on a household object stays an object."""
    vol, scene = _room_view(1, azimuth)
    res = analyse_volume(vol, SegmentOptions(superquadrics=False))
    owners = _owners(res, scene)
    walls = {s for s, o in owners.items() if o in WALLS}
    assert walls, "the view sees a wall or the cabinet"
    assert walls <= set(res.background)
    assert all(owners[s] in WALLS + ("table", "nothing") for s in res.background)
    assert set(res.background.values()) <= {BELOW, BEYOND}
    assert {s.id for s in res.objects} == set(owners) - set(res.background)


def test_an_object_cut_by_the_image_border_is_not_background():
    """The bleach bottle of household seed 2 stands at the table's near edge and the image's lower border cuts
    its foot off, with the table under it: most of its points lie past the table's visible extent, but there the
    volume never saw the plane level (unknown, not empty), so it stays an object (the hull alone called it
    background)."""
    sc = make_scenario(2, width=640, height=480, frames=24, noise=True, layout="household")
    scene = sc.scene_after
    T = sc.frames[0].T_world_camera
    depth, rgb = DepthSensor(sc.K, 640, 480, noise=True, seed=2, **PHOTOMETRIC).render(scene, T, frame_seed=0)
    vol = TernaryVolume(size=1.6, resolution=320, origin=np.array([-0.8, -0.8, 0.3]), color=True)
    vol.integrate(depth, sc.K, T, rgb)
    res = analyse_volume(vol, SegmentOptions(superquadrics=False))
    owners = _owners(res, scene)
    assert "bleach" in {owners[s.id] for s in res.objects}
    assert not res.background


def test_segments_json_kinds_and_ranks(tmp_path):
    """segments.json: background segments are kind "background" with their reason and no rank, after the
    objects, whose ranks run 1..n; `--background-margin 0` makes every segment an object again."""
    vol, _ = _room_view(1, 4.7)
    vol.save(tmp_path / "volume.npz")
    docs = {}
    for margin in ("0.05", "0"):
        out = tmp_path / f"seg_{margin}"
        r = CliRunner().invoke(cli, ["segment", str(tmp_path / "volume.npz"), "-o", str(out), "--no-superquadrics",
                                      "--quiet", "--background-margin", margin])
        assert r.exit_code == 0, r.output
        docs[margin] = json.loads((out / "segments.json").read_text())
    segs = [s for s in docs["0.05"]["segments"] if s["kind"] != "support_plane"]
    kinds = [s["kind"] for s in segs]
    assert "background" in kinds and kinds == sorted(kinds, key=lambda k: k == "background")
    assert [s["rank"] for s in segs if s["kind"] == "object"] == list(range(1, kinds.count("object") + 1))
    assert all(s["rank"] is None and s["background_reason"] in (BELOW, BEYOND)
               for s in segs if s["kind"] == "background")
    assert sum(docs["0.05"]["stats"]["background_segments"].values()) == kinds.count("background")
    assert {s["kind"] for s in docs["0"]["segments"]} == {"object", "support_plane"}
    assert len(docs["0"]["segments"]) == len(docs["0.05"]["segments"])


def _grid(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack(np.meshgrid(a, b), axis=-1).reshape(-1, 2)


def test_below_the_table_is_background_without_a_volume():
    """From a bare cloud (no volume: nothing says where the table ends) only the rule "below the support plane"
    applies: a chair back beside the table, mostly under its height, is background (one wholly under it joins
    the support plane, segments.py step 5), a wall standing beyond the table is still an object."""
    rng = np.random.default_rng(0)
    step = np.arange(0, 1, 0.008)
    table = np.c_[_grid(step - 0.5, step[:100] - 0.4), np.full(12500, 0.7)]
    box = np.c_[rng.uniform(-0.05, 0.05, (1500, 2)), np.zeros(1500)]
    box[:, 2] = 0.76 + 0.04 * rng.choice([-1.0, 1.0], 1500)  # two faces, then bent into a rounded lump
    chair = np.c_[np.full(4400, 0.9), _grid(step[:50] - 0.2, step[:88] + 0.2)]  # rises 0.2 m past the table
    xz = _grid(step - 0.5, step[:88] + 0.8)
    wall = np.c_[xz[:, 0], np.full(11000, 1.2), xz[:, 1]]
    pts = np.concatenate([table, box, chair, wall])
    box_n = box - [0, 0, 0.76]
    nrm = np.concatenate([np.tile([0, 0, 1.0], (len(table), 1)), box_n / np.linalg.norm(box_n, axis=1)[:, None],
                          np.tile([-1.0, 0, 0], (len(chair), 1)), np.tile([0, -1.0, 0], (len(wall), 1))])
    opts = SegmentOptions(superquadrics=False, color=False)
    res = analyse_cloud(pts, nrm, replace(opts, segmentation=replace(opts.segmentation, up=(0.0, 0.0, 1.0))))
    seg = res.segmentation
    chair_ids = set(np.unique(seg.labels[seg.points[:, 0] > 0.85])) - {-1, 0}
    wall_ids = set(np.unique(seg.labels[seg.points[:, 1] > 1.15])) - {-1, 0}
    assert chair_ids and all(res.background.get(int(s)) == BELOW for s in chair_ids)
    assert wall_ids and not wall_ids & set(res.background)
