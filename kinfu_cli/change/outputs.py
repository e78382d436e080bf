"""The files of `kinfu diff`: changes.json, regions/<id>.ply (each region's voxel centres) and changes.ply (every
region, removed red and added green; not written when nothing changed), each written atomically with open3d's
PLY writer."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.change.diff import ChangeResult
from kinfu_cli.core.atomic import atomic_dir, atomic_path, write_json
from kinfu_cli.core.errors import VolumeError

COLOURS = {"removed": (0.9, 0.1, 0.1), "added": (0.1, 0.8, 0.1)}
# every entry `kinfu diff` writes in its output folder: the rest of a shared folder is left alone
CHANGE_ENTRIES = ("changes.json", "changes.ply", "regions")


def _write_cloud(path: Path, points: np.ndarray, colours: np.ndarray) -> Path:
    import open3d as o3d  # heavy; only the PLY writer is needed

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64).reshape(-1, 3)))
    pc.colors = o3d.utility.Vector3dVector(np.asarray(colours, dtype=np.float64).reshape(-1, 3))
    with atomic_path(path) as tmp:
        if not o3d.io.write_point_cloud(str(tmp), pc, write_ascii=False):
            raise VolumeError(f"{path}: open3d could not write the point cloud")
    return path


def write_change_outputs(result: ChangeResult, outdir: str | os.PathLike) -> dict[str, Path]:
    """changes.json, changes.ply (when a region was found) and regions/<id>.ply in `outdir`; returns name -> path."""
    out = Path(outdir)
    files: dict[str, Path] = {}
    with atomic_dir(out / "regions") as folder:  # recorded as kinfu's own in the parent, so a rerun may replace it
        for r in result.regions:
            path = _write_cloud(folder / f"{r.id}.ply", r.points, np.tile(COLOURS[r.kind], (len(r.points), 1)))
            files[f"regions/{r.id}.ply"] = out / "regions" / path.name
    if result.regions:  # open3d writes no empty cloud; changes.json says "changes_ply": null then
        files["changes.ply"] = _write_cloud(out / "changes.ply", np.concatenate([r.points for r in result.regions]),
                                            np.concatenate([np.tile(COLOURS[r.kind], (len(r.points), 1))
                                                            for r in result.regions]))
    files["changes.json"] = write_json(out / "changes.json", result.to_json())
    return files
