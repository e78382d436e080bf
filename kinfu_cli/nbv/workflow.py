"""`kinfu nbv` as a library call: load volume and POIs, optionally ForgetAround, rank each POI."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.pois import poi_frame_warnings
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.fusion.volume import load_grid
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.nbv.gains import get_gain
from kinfu_cli.nbv.ranking import (PoiRanking, check_region_inside, estimate_table_z, forget_around, load_pois,
                                   rank_poi)
from kinfu_cli.nbv.raycast import RayVolume
from kinfu_cli.nbv.viewpoints import read_candidates, sphere_viewpoints


@dataclass
class NbvOptions:
    """Options of `kinfu nbv` (names as on the command line). table_z: "auto", "none" or metres."""

    gain: str = "unknown"
    clear: bool = False
    top: int = 10
    candidates: str | os.PathLike | None = None
    sphere: dict = field(default_factory=dict)
    poi_radius: float | None = None
    inc_th: float | None = None
    table_z: str | float | None = "auto"
    clearance: float = 0.0
    share_rolls: bool = True
    optimistic: bool = False


def resolve_table_z(grid: TernaryGrid, table_z) -> float | None:
    if table_z is None or table_z == "none":
        return None
    if table_z == "auto":
        return estimate_table_z(grid)
    return float(table_z)


def run_nbv(volume_path: str | os.PathLike, pois_path: str | os.PathLike, camera: CameraModel,
            opts: NbvOptions, quiet: bool = True) -> tuple[dict, TernaryGrid, list[PoiRanking]]:
    """Rank views for every POI of `pois_path` in the volume; returns (views.json document, grid, rankings)."""
    get_gain(opts.gain)
    if opts.poi_radius is not None and not opts.poi_radius > 0:
        raise ConfigError(f"--poi-radius: expected a positive radius in metres, got {opts.poi_radius}")
    if opts.inc_th is not None and not opts.inc_th >= 0:
        raise ConfigError(f"--inc-th: expected a non-negative gain, got {opts.inc_th}")
    if opts.clearance < 0:
        raise ConfigError(f"--clearance: expected a non-negative distance, got {opts.clearance}")
    pois = load_pois(pois_path, opts.poi_radius)
    grid = load_grid(volume_path)
    for p in pois:
        check_region_inside(grid, p.position, f"{pois_path}: POI {p.id}")
    cand = read_candidates(opts.candidates) if opts.candidates is not None else None
    cleared = {}
    if opts.clear:
        for p in pois:
            cleared[p.id] = forget_around(grid, p.position, p.radius)
    table_z = resolve_table_z(grid, opts.table_z)
    vol = RayVolume.from_grid(grid)
    per_poi = [cand if cand is not None else sphere_viewpoints(p.position, **opts.sphere) for p in pois]
    total = sum(len(c) for c in per_poi)

    from kinfu_cli.core.progress import progress_enabled

    bar = None
    if progress_enabled(quiet):
        import sys

        from tqdm import tqdm

        bar = tqdm(total=total, desc="nbv candidates", unit="view", file=sys.stderr, leave=False, dynamic_ncols=True)
    rankings = []
    try:
        for p, poses in zip(pois, per_poi):
            r = rank_poi(vol, p.position, camera, poi_id=p.id, radius=p.radius, gain=opts.gain, candidates=poses,
                         inc_th=opts.inc_th, table_z=table_z, clearance=opts.clearance,
                         share_rolls=opts.share_rolls, optimistic=opts.optimistic,
                         progress_cb=bar.update if bar is not None else None)
            if opts.clear:
                r.extra["cleared_voxels"] = cleared[p.id]
            rankings.append(r)
    finally:
        if bar is not None:
            bar.close()
    doc = {
        "volume": str(volume_path), "pois_file": str(pois_path), "gain": opts.gain,
        "gain_unit": get_gain(opts.gain).unit, "cleared": bool(opts.clear),
        "candidates": str(opts.candidates) if opts.candidates is not None else {"sphere": _sphere_doc(opts.sphere)},
        "camera": camera.to_dict(), "table_z": table_z, "clearance": opts.clearance,
        "share_rolls": opts.share_rolls, "optimistic": opts.optimistic,
        "voxel_size": grid.voxel_size, "shape": list(grid.shape),
        "pois": [r.to_dict(top=opts.top) for r in rankings],
        "warnings": poi_frame_warnings(pois_path, grid.frame, "--pois"),
    }
    return doc, grid, rankings


def _sphere_doc(sphere: dict) -> dict:
    d = dict(radius=0.8, lon_step=30.0, lat_min=0.0, lat_max=90.0, lat_step=10.0, roll_step=45.0)
    d.update(sphere)
    return d


def summary_lines(doc: dict) -> list[str]:
    """Human-readable summary of a views.json document."""
    lines = []
    for p in doc["pois"]:
        rej = ", ".join(f"{k} {v}" for k, v in p["rejected"].items() if v) or "none"
        state = "reconstructed" if p["reconstructed"] else "not reconstructed"
        x, y, z = p["position"]
        lines.append(f"POI {p['id']} at ({x:.3f}, {y:.3f}, {z:.3f}) r={p['radius']:.2f} m: {p['candidates']} candidates,"
                     f" rejected: {rej}; best {doc['gain']} gain {p['best_gain']:.1f} (IncTh {p['inc_th']:.1f}): {state}")
        lines.append("  rank      gain   unknown  occupied  empty-exit  position")
        for i, v in enumerate(p["views"][:10]):
            px, py, pz = v["position"]
            lines.append(f"  {i + 1:4d} {v['gain']:9.1f} {v['rays_unknown']:9d} {v['rays_occupied']:9d} "
                         f"{v['rays_empty_exit']:11d}  ({px:.3f}, {py:.3f}, {pz:.3f})")
    return lines



def run_objects(volume_path: str | os.PathLike, camera: CameraModel, *, gain: str = "unknown", table_z="auto",
                score_threshold: float = 0.0, top: int = 10) -> dict:
    """`kinfu nbv --mode objects`: the object-driven planner (thesis Alg. 4, kinfu_cli.nbv.objects) scored
    with this module's ray caster; returns the views.json document."""
    from kinfu_cli.nbv.objects import nbv_scorer, plan_object_views_for_volume
    from kinfu_cli.core.poses import matrix_to_quaternion
    from kinfu_cli.segmentation.pipeline import load_segment_input

    get_gain(gain)
    volume = load_segment_input(volume_path)
    grid = volume.ternary_grid() if hasattr(volume, "ternary_grid") else volume
    tz = resolve_table_z(grid, table_z)
    plan = plan_object_views_for_volume(volume, camera, scorer=nbv_scorer(grid, camera, gain=gain, table_z=tz),
                                        score_threshold=score_threshold, table_z=tz)
    doc = plan.to_json(top=top or 10**9)
    for v in doc["views"]:
        T = np.asarray(v["pose"])
        v.update(position=T[:3, 3].tolist(), quaternion=matrix_to_quaternion(T[:3, :3]).tolist(), gain=v["score"])
    return {"mode": "objects", "volume": str(volume_path), "gain": gain, "gain_unit": get_gain(gain).unit,
            "camera": camera.to_dict(), "table_z": tz, "voxel_size": grid.voxel_size, "shape": list(grid.shape),
            "score_threshold": score_threshold, **doc}


def objects_summary_lines(doc: dict) -> list[str]:
    if doc["pose"] is None:
        return [f"no view scores above {doc['score_threshold']} on any segment ({len(doc['attempts'])} tried): "
                "the objects are considered reconstructed"]
    r = doc["region"]
    c = r["center"]
    lines = [f"segment {doc['segment_id']} (region centre ({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}), r={r['radius']:.2f} m):"
             f" best {doc['gain']} gain {doc['score']:.1f}; {doc['candidates_evaluated']} of "
             f"{doc['candidates_total']} candidates ray-cast",
             "  rank      gain  position"]
    for i, v in enumerate(doc["views"][:10]):
        px, py, pz = v["position"]
        lines.append(f"  {i + 1:4d} {v['gain']:9.1f}  ({px:.3f}, {py:.3f}, {pz:.3f})")
    return lines
