"""The error-coloured mesh of `kinfu eval fusion`: the reconstruction coloured by its distance to the truth."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import open3d as o3d

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.reconstruction import Reconstruction


def write_error_mesh(path: str | os.PathLike, rec: Reconstruction, distances: np.ndarray, vmax: float) -> Path:
    """The reconstruction with vertex colours by distance to the truth (matplotlib 'turbo': dark blue 0 .. dark
    red >= vmax; grey where not evaluated), written atomically (PLY/OBJ/... by suffix)."""
    from matplotlib import colormaps  # heavy: loaded only when this mesh is asked for

    d = np.asarray(distances, dtype=np.float64)
    cols = colormaps["turbo"](np.clip(np.nan_to_num(d, nan=0.0) / vmax, 0.0, 1.0))[:, :3]
    cols[~np.isfinite(d)] = 0.6
    path = Path(path)
    with atomic_path(path) as tmp:
        if rec.is_cloud:
            geo = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rec.vertices))
            geo.colors = o3d.utility.Vector3dVector(cols)
            ok = o3d.io.write_point_cloud(str(tmp), geo)
        else:
            geo = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(rec.vertices),
                                            o3d.utility.Vector3iVector(rec.triangles.astype(np.int32)))
            geo.vertex_colors = o3d.utility.Vector3dVector(cols)
            ok = o3d.io.write_triangle_mesh(str(tmp), geo)
        if not ok:
            raise ConfigError(f"{path}: open3d could not write this file type (use .ply)", parameter="error_mesh")
    return path
