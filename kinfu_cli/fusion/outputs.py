"""The files of a fusion run: mesh, surface cloud, volume, ternary labels, camera trajectory (TUM) and the report
(report.json).

`write_fusion_outputs(result, outdir)` writes the first five, each atomically; `fusion_report(result)` is the
report dict, which the caller writes last (after any plots it adds to the folder, named in extra_outputs).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import save_ternary
from kinfu_cli.fusion.pipeline import FusionResult, ate_vs_given
from kinfu_cli.io.tum import write_tum

OUTPUTS = ("mesh.ply", "cloud.ply", "volume.npz", "ternary.npz", "trajectory.tum", "report.json")
_EMPTY_PLY = "ply\nformat ascii 1.0\ncomment kinfu: no surface in the grid\n{elements}end_header\n"


def write_fusion_outputs(result: FusionResult, outdir: str | os.PathLike) -> None:
    """Write mesh.ply, cloud.ply, volume.npz and ternary.npz into outdir (made when missing). A grid in which
    nothing was observed is an error (it sits away from every depth reading); one with observed space but no
    surface gets valid PLY files without vertices."""
    import open3d as o3d  # heavy: only when writing

    if result.counts.get("occupied", 0) + result.counts.get("empty", 0) == 0 and not result.cleared_spheres:
        vol = result.volume
        hi = vol.origin + np.array(vol.shape) * vol.voxel_size
        box = " x ".join(f"[{a:.3f}, {b:.3f}]" for a, b in zip(vol.origin, hi))
        raise VolumeError(f"{result.recording}: no depth reading of the {result.frames_used} frames fused falls "
                          f"inside the grid {box} m: nothing was observed (move or enlarge the grid: origin, size)")
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    with atomic_path(outdir / "mesh.ply") as tmp:
        if len(result.mesh.vertices) == 0:
            tmp.write_text(_EMPTY_PLY.format(elements="element vertex 0\nproperty float x\nproperty float y\n"
                                                      "property float z\nelement face 0\n"
                                                      "property list uchar int vertex_indices\n"))
        elif not o3d.io.write_triangle_mesh(str(tmp), result.mesh):
            raise OSError(f"could not write {outdir / 'mesh.ply'}")
    with atomic_path(outdir / "cloud.ply") as tmp:
        if len(result.cloud.points) == 0:
            tmp.write_text(_EMPTY_PLY.format(elements="element vertex 0\nproperty float x\nproperty float y\n"
                                                      "property float z\n"))
        elif not o3d.io.write_point_cloud(str(tmp), result.cloud):
            raise OSError(f"could not write {outdir / 'cloud.ply'}")
    result.volume.save(outdir / "volume.npz")
    save_ternary(outdir / "ternary.npz", result.grid)
    write_trajectory(result, outdir / "trajectory.tum")


def write_trajectory(result: FusionResult, path: str | os.PathLike) -> Path:
    """The camera pose of every frame fused, at its stamp, as a TUM trajectory (`evo_ape tum` compares it with
    the recording's poses written by `kinfu export` with trajectory tum)."""
    return write_tum(path, result.camera_stamps_ns, np.array(result.camera_poses).reshape(-1, 4, 4),
                     comment=f"kinfu fuse {result.recording}: poses {result.pose_mode} ({result.pose_source}), "
                             f"frame {result.volume.frame or 'unnamed'}")


def fusion_report(result: FusionResult, extra_outputs: Iterable[str] = ()) -> dict:
    """The report of a fusion run (report.json): frames used and dropped, poses, the world's up direction
    (up, up_source, up_evidence: fusion.up) and the depth intrinsics fused, tracking, grid, filters,
    cleared spheres, counts, bounding boxes, mesh and cloud sizes, timing (with the total until now), the
    output files (OUTPUTS, then extra_outputs) and warnings."""
    vol = result.volume
    stats = result.frame_stats
    depth_filter = result.depth_filter
    track_log = result.tracking
    timing = {**result.timing, "total": time.perf_counter() - result.started}
    return {
        "recording": result.recording,
        "roles": result.roles.as_dict(),
        "pose_mode": result.pose_mode,
        "pose_source": result.pose_source,
        "world_frame": vol.frame,
        "up": None if vol.up is None else vol.up.tolist(),
        "up_source": result.up.get("source", vol.up_source),
        "up_evidence": {k: v for k, v in result.up.items() if k not in ("up", "source")},
        "intrinsics": vol.intrinsics,
        "frames": {"depth_messages": stats.depth_messages, "used": result.frames_used,
                   "skipped_every": stats.skipped, "without_color": stats.without_color,
                   "dropped": result.dropped, "dropped_total": int(sum(result.dropped.values())),
                   "outside_grid": list(result.frames_outside_grid),
                   "every": result.every, "start_s": result.start_s, "end_s": result.end_s,
                   **({"color_registration": stats.color_registration} if stats.color_registration else {}),
                   **({"depth_units_m": stats.depth_units} if stats.depth_units is not None else {})},
        "tracking": None if track_log is None else _tracking_summary(track_log),
        "grid": {"origin": vol.origin.tolist(), "voxel_size": vol.voxel_size, "shape": list(vol.shape),
                 "size_m": (np.array(vol.shape) * vol.voxel_size).tolist(), "truncation": vol.truncation,
                 "max_weight": vol.max_weight, "min_depth": depth_filter.min_depth,
                 "max_depth": depth_filter.max_depth, "placement": result.placement,
                 "blocks_stored": vol.n_blocks_allocated, "memory_MB": round(vol.memory_bytes() / 2**20, 1),
                 "frames_in_volume": vol.frames_integrated,
                 "color": vol.color, "color_mode": vol.color_mode,
                 "sizing": result.grid_sizing,
                 "face_contacts": result.face_contacts},
        "filters": {"range": [depth_filter.min_depth, depth_filter.max_depth], "fill_gaps": depth_filter.fill_gaps,
                    "gap_pixels_filled": depth_filter.gap_pixels, "bilateral": depth_filter.bilateral,
                    "shadow_veil": depth_filter.shadow_filter},
        "cleared_spheres": result.cleared_spheres,
        "counts": result.counts,
        "bounding_box": result.bounding_box,
        "mesh": {"vertices": len(result.mesh.vertices), "triangles": len(result.mesh.triangles)},
        "cloud": {"points": len(result.cloud.points)},
        "timing_s": {k: round(v, 3) for k, v in timing.items()},
        "outputs": list(OUTPUTS) + list(extra_outputs),
        "warnings": result.warnings,
    }


def _tracking_summary(track_log: list[dict]) -> dict:
    """The report's tracking section: every tracked frame, the lost ones, those hint mode fused at their TF pose
    because ICP failed (tf_fallback), how many had ICP's colour term (photometric), and the error against the given poses (when the recording has them: a
    tracked pose's camera position minus the given one, RMSE and max, over the frames ICP placed)."""
    kept = [t for t in track_log if not t["lost"]]
    fallback = [t["index"] for t in track_log if t.get("tf_fallback")]
    return {
        "frames": track_log, "tracked": len(track_log), "lost_frames": [t["index"] for t in track_log if t["lost"]],
        "lost": len(track_log) - len(kept), "tf_fallback_frames": fallback, "tf_fallback": len(fallback),
        "relocalised": int(sum(bool(t.get("relocalised")) and not t.get("tf_fallback") for t in kept)),
        "photometric": int(sum(bool(t.get("photometric")) for t in track_log)),
        "mean_fitness": float(np.mean([t["fitness"] for t in track_log])) if track_log else None,
        "ate_vs_given_m": ate_vs_given(track_log)}
