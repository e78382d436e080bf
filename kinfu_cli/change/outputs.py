"""The files of `kinfu diff`: changes.json, regions/<id>.ply (each region's voxel centres) and changes.ply (every
region, removed red and added green), each written atomically with open3d's PLY writer."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.change.diff import ChangeResult
from kinfu_cli.core.atomic import atomic_path, write_json
from kinfu_cli.core.errors import VolumeError

COLOURS = {"removed": (0.9, 0.1, 0.1), "added": (0.1, 0.8, 0.1)}


def _write_cloud(path: Path, points: np.ndarray, colours: np.ndarray) -> Path:
    import open3d as o3d  # heavy; only the PLY writer is needed

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64).reshape(-1, 3)))
    pc.colors = o3d.utility.Vector3dVector(np.asarray(colours, dtype=np.float64).reshape(-1, 3))
    with atomic_path(path) as tmp:
        if not o3d.io.write_point_cloud(str(tmp), pc, write_ascii=False):
            raise VolumeError(f"{path}: open3d could not write the point cloud")
    return path


def write_change_outputs(result: ChangeResult, outdir: str | os.PathLike) -> dict[str, Path]:
    """changes.json, changes.ply and regions/<id>.ply in `outdir`; returns name -> path."""
    out = Path(outdir)
    files: dict[str, Path] = {}
    for r in result.regions:
        name = f"regions/{r.id}.ply"
        files[name] = _write_cloud(out / name, r.points, np.tile(COLOURS[r.kind], (len(r.points), 1)))
    pts = [r.points for r in result.regions]
    cols = [np.tile(COLOURS[r.kind], (len(r.points), 1)) for r in result.regions]
    files["changes.ply"] = _write_cloud(out / "changes.ply", np.concatenate(pts) if pts else np.zeros((0, 3)),
                                        np.concatenate(cols) if cols else np.zeros((0, 3)))
    files["changes.json"] = write_json(out / "changes.json", result.to_json())
    return files
