"""Single-view segment counts against visible objects: the stand-in for issue 12's real tabletop target
("single-view RealSense scenes of 5-11 household objects: segment count within +-30 % of the true object count").

Each view is one 640 x 480 frame of a synthetic scenario (`make_scenario`, the scene after its change), rendered
with the photometric effects of the segmentation benchmark, fused alone into a 5 mm colour volume and segmented
(`analyse_volume`, no superquadrics). An object is visible when >= 30 points of the segmented cloud lie within
15 mm of its labelled surface (`scene_label_cloud`); each segment is given the object most of its points lie on.
An object is split when two or more segments are given to it; a segment merges when a second object holds at
least a quarter of its points.

--room: the scene gets walls 1.6 m from the table's centre on all four sides and a cabinet on the floor, the
views are taken from 1.1 m at 30 deg elevation from four sides (walls and cabinet in view), and each is fused into
a grid around all it sees at 3/512 m, as `kinfu fuse --size auto` does. Segments of kind "background"
(segmentation/background.py) are counted apart: the row says how many, and how many lie mostly on an object
(`bg_on_objects`, which should be 0).

Layouts: "objects" (primitives, `segmentation_scene`) and "household" (YCB-like composites,
`sim.household.household_scene`). Seeds are fixed before looking: household tuning 0-5, held-out 6-9 (run the
held-out ones once, at the end, with --held-out); objects 0, 1, 8-11 (the sv.py set).

Usage: PYTHONPATH=. python benchmarks/bench_single_view.py [--layouts objects,household] [--held-out] [--room]
       [--seeds 0,1] [--frames 0,6,12,18] [--up none|z] [--color mean|mode] [--json out.json]
       [--param NAME=VALUE] [--sensor '{"baseline": 0.05, "ir_focal": 385}']
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.poses import look_at
from kinfu_cli.evaluation.segments import PHOTOMETRIC
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume
from kinfu_cli.segmentation.segments import SegmentationParams
from kinfu_cli.sim.household import object_kind
from kinfu_cli.sim.scenario import make_scenario
from kinfu_cli.sim.scene import resting_object, scene_label_cloud
from kinfu_cli.sim.sensor import DepthSensor

W, H = 640, 480
SEEDS = {"objects": {"tuning": [0, 1, 8, 9, 10, 11], "held-out": []},
         "household": {"tuning": [0, 1, 2, 3, 4, 5], "held-out": [6, 7, 8, 9]}}
MIN_POINTS = 30  # points of an object in the cloud for it to count as visible
NEAR = 0.015  # m: a cloud point lies on the labelled surface within this distance
MERGE_SHARE = 0.25


ROOM_SCENERY = ("wall_n", "wall_s", "wall_e", "wall_w", "cabinet")
ROOM_AZIMUTHS = (0.0, 1.6, 3.1, 4.7)  # rad: views from +x, +y, -x, -y of the table's centre
AUTO_VOXEL = 3 / 512  # m: kinfu fuse's default voxel with --size auto


def with_room(scene):
    """The scene inside four walls 1.6 m from the table's centre, with a cabinet on the floor by one corner."""
    x, y = scene.table.center
    wall, white = {"x": 5, "y": 0.1, "z": 2.6}, (0.85, 0.85, 0.8)
    side = {"x": 0.1, "y": 5, "z": 2.6}
    extra = (resting_object("wall_n", "box", wall, xy=(x, y + 1.6), colour=white),
             resting_object("wall_s", "box", wall, xy=(x, y - 1.6), colour=white),
             resting_object("wall_e", "box", side, xy=(x + 1.6, y), colour=(0.8, 0.82, 0.85)),
             resting_object("wall_w", "box", side, xy=(x - 1.6, y), colour=(0.8, 0.82, 0.85)),
             resting_object("cabinet", "box", {"x": 0.6, "y": 0.5, "z": 0.9}, xy=(x + 1.0, y + 1.0),
                            colour=(0.5, 0.35, 0.2)))
    return replace(scene, objects=scene.objects + extra)


def room_view(scene, azimuth: float, distance: float = 1.1, elevation_deg: float = 30.0) -> np.ndarray:
    """Camera pose (x right, y down, z forward) looking at the table's centre 5 cm over its top."""
    target = np.array([scene.table.center[0], scene.table.center[1], scene.table.top_z + 0.05])
    e = np.radians(elevation_deg)
    p = target + distance * np.array([np.cos(azimuth) * np.cos(e), np.sin(azimuth) * np.cos(e), np.sin(e)])
    return look_at(p, target)


def _view_grid(scene, depth, K, T, room: bool, color: str) -> TernaryVolume:
    """The table's 1.6 m box, or (room) a grid around all the view sees at AUTO_VOXEL, as kinfu fuse's."""
    if not room:
        c = np.array([scene.table.center[0], scene.table.center[1], scene.table.top_z])
        return TernaryVolume(size=1.6, resolution=320, origin=c - np.array([0.8, 0.8, 0.4]), color=True,
                             color_mode=color)
    v, u = np.nonzero(depth > 0)
    z = depth[v, u].astype(np.float64)
    pts = (T @ np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z, np.ones_like(z)]))[:3].T
    lo, hi = pts.min(axis=0) - 0.05, pts.max(axis=0) + 0.05
    res = np.ceil((hi - lo) / AUTO_VOXEL).astype(int)
    return TernaryVolume(size=tuple(res * AUTO_VOXEL), resolution=tuple(int(r) for r in res), origin=lo, color=True,
                         color_mode=color)


def segment_view(scene, sensor, K, T, frame_seed: int, up, color: str, overrides: dict | None = None,
                 room: bool = False):
    """(points, segment labels, background segment ids, seconds wall, seconds CPU) of one view fused alone and
    segmented."""
    w0, c0 = time.perf_counter(), time.process_time()
    depth, rgb = sensor.render(scene, T, frame_seed=frame_seed)
    vol = _view_grid(scene, depth, K, T, room, color)
    vol.integrate(depth, K, T, rgb)
    o = SegmentOptions(superquadrics=False)
    o = replace(o, segmentation=replace(o.segmentation, up=up, **(overrides or {})))
    res = analyse_volume(vol, o)
    return (res.segmentation.points, res.segmentation.labels, set(res.background), time.perf_counter() - w0,
            time.process_time() - c0)


def score_view(points, labels, gp, gl, names: dict, background: set = frozenset(), scenery=()) -> dict:
    """Segments (objects only: background ones apart), visible objects (not the room's scenery), and per object
    the segments given to it; per segment its main object."""
    d, idx = cKDTree(gp).query(points)
    g = np.where(d < NEAR, gl[idx], -1)
    segs = [int(s) for s in np.unique(labels) if s > 0 and int(s) not in background]
    visible = [int(o) for o in np.unique(g) if o > 0 and names[o] not in scenery and np.sum(g == o) >= MIN_POINTS]
    given = defaultdict(list)
    merges, detail = [], []
    bg_on_objects = 0
    for s in background:
        obj, cnt = np.unique(g[labels == s], return_counts=True)
        main = int(obj[np.argmax(cnt)])
        bg_on_objects += int(main > 0 and names[main] not in scenery)
    for s in segs:
        obj, cnt = np.unique(g[labels == s], return_counts=True)
        order = np.argsort(-cnt)
        main = int(obj[order[0]])
        given[main].append(int(cnt.sum()))
        name = names.get(main, "table" if main == 0 else "none")
        detail.append(f"{name}:{int(cnt.sum())}")
        second = [(int(obj[k]), int(cnt[k])) for k in order[1:] if obj[k] > 0 and cnt[k] >= MERGE_SHARE * cnt.sum()]
        if main > 0 and second:
            merges.append([name] + [names.get(o, str(o)) for o, _ in second])
    return {"segments": len(segs), "visible": len(visible), "detail": sorted(detail),
            "background": len(background), "bg_on_objects": bg_on_objects,
            "split": {names[o]: len(given[o]) for o in visible if len(given[o]) >= 2},
            "missed": [names[o] for o in visible if not given[o]], "merges": merges,
            "visible_ids": [names[o] for o in visible]}


def run(layout: str, seeds, frames, up, color: str, overrides: dict | None = None, sensor_args: dict | None = None,
        room: bool = False) -> list[dict]:
    rows = []
    for seed in seeds:
        sc = make_scenario(seed, width=W, height=H, frames=24, noise=True, layout=layout)
        scene = with_room(sc.scene_after) if room else sc.scene_after
        sensor = DepthSensor(sc.K, W, H, noise=True, seed=seed, **(PHOTOMETRIC | (sensor_args or {})))
        gp, gl = scene_label_cloud(scene)
        names = {scene.label_of(o.id): o.id for o in scene.present_objects}
        views = ([(k, room_view(scene, a)) for k, a in enumerate(ROOM_AZIMUTHS)] if room else
                 [(k, sc.frames[k].T_world_camera) for k in frames])
        for k, T in views:
            pts, lab, bg, wall, cpu = segment_view(scene, sensor, sc.K, T, k, up, color, overrides, room)
            r = score_view(pts, lab, gp, gl, names, bg, ROOM_SCENERY if room else ()) | {
                "layout": layout, "seed": seed, "frame": k, "wall_s": wall, "cpu_s": cpu}
            rows.append(r)
            print(f"{layout} seed {seed} {'view' if room else 'frame'} {k}: segments {r['segments']} visible "
                  f"{r['visible']} background {r['background']} (on objects {r['bg_on_objects']}) "
                  f"({wall:.1f} s, cpu {cpu:.1f} s) split {r['split'] or '-'} merged {r['merges'] or '-'} "
                  f"missed {r['missed'] or '-'} | {' '.join(r['detail'])}", flush=True)
    return rows


def summary(rows: list[dict]) -> dict:
    a = np.array([(r["segments"], r["visible"]) for r in rows if r["visible"] > 0], float)
    ratio = a[:, 0] / a[:, 1]
    kinds = defaultdict(lambda: [0, 0, 0])  # views visible, views split, views merged
    for r in rows:
        for oid in r["visible_ids"]:
            kinds[object_kind(oid)][0] += 1
        for oid in r["split"]:
            kinds[object_kind(oid)][1] += 1
        for m in r["merges"]:
            for oid in m:
                kinds[object_kind(oid)][2] += 1
    return {"views": len(a), "mean_ratio": float(ratio.mean()),
            "background": int(sum(r["background"] for r in rows)),
            "bg_on_objects": int(sum(r["bg_on_objects"] for r in rows)), "within_30": float(np.mean(np.abs(ratio - 1) <= 0.3)),
            "within_30_count": int(np.sum(np.abs(ratio - 1) <= 0.3)),
            "wall_s_per_view": float(np.mean([r["wall_s"] for r in rows])),
            "cpu_s_per_view": float(np.mean([r["cpu_s"] for r in rows])),
            "kinds": {k: {"visible": v[0], "split": v[1], "merged": v[2]} for k, v in sorted(kinds.items())}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", default="objects,household")
    ap.add_argument("--held-out", action="store_true", help="the held-out seeds instead of the tuning ones")
    ap.add_argument("--seeds", default=None, help="comma-separated seeds (overrides the fixed split)")
    ap.add_argument("--frames", default="0,6,12,18")
    ap.add_argument("--up", default="none", help="none, z, or x,y,z")
    ap.add_argument("--color", default="mean", choices=("mean", "mode"))
    ap.add_argument("--json", default=None)
    ap.add_argument("--room", action="store_true", help="walls and a cabinet round the table, views that see them, "
                                                        "a grid around all each view sees (see the docstring)")
    ap.add_argument("--sensor", default="{}", help='DepthSensor keywords as JSON, e.g. {"baseline": 0.05}')
    ap.add_argument("--param", action="append", default=[],
                    help="a SegmentationParams field as name=value (none for None), repeatable")
    a = ap.parse_args()
    up = None if a.up == "none" else (0.0, 0.0, 1.0) if a.up == "z" else tuple(float(x) for x in a.up.split(","))
    frames = [int(f) for f in a.frames.split(",")]
    overrides = {k: (None if v == "none" else type(getattr(SegmentationParams(), k) or 0.0)(v))
                 for k, v in (p.split("=", 1) for p in a.param)}
    out = {}
    for layout in a.layouts.split(","):
        seeds = ([int(s) for s in a.seeds.split(",")] if a.seeds else
                 SEEDS[layout]["held-out" if a.held_out else "tuning"])
        if not seeds:
            continue
        rows = run(layout, seeds, frames, up, a.color, overrides, json.loads(a.sensor), a.room)
        s = summary(rows)
        out[layout] = {"rows": rows, "summary": s}
        print(f"== {layout} seeds {seeds} frames {frames} up {a.up} colour {a.color} {a.param or ''} {a.sensor}: {s['views']} views, "
              f"mean ratio {s['mean_ratio']:.3f}, within +-30 % {s['within_30_count']}/{s['views']} "
              f"({s['within_30']:.2f}), background segments {s['background']} (on objects {s['bg_on_objects']}), "
              f"{s['wall_s_per_view']:.1f} s/view wall, {s['cpu_s_per_view']:.1f} s CPU")
        for k, v in s["kinds"].items():
            print(f"   {k:12s} visible {v['visible']:3d}  split {v['split']:3d}  merged {v['merged']:3d}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
