"""The model surface seen from a pose, ray cast from a TernaryVolume: the target of frame-to-model ICP.

The kernel lives in kernels.raycast_kernel; TernaryVolume.raycast calls it.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.camera import scaled_intrinsics


def model_cloud(volume, K: np.ndarray, width: int, height: int, T_world_camera: np.ndarray, scale: float = 0.5):
    """open3d PointCloud (world) with normals of the model surface seen from a pose, ray cast at `scale` of
    the image size: the target of frame-to-model ICP."""
    import open3d as o3d  # heavy: only when tracking

    w = max(8, int(round(width * scale)))
    h = max(8, int(round(height * scale)))
    _, normals, verts = volume.raycast(scaled_intrinsics(K, w / width), w, h, T_world_camera)
    ok = np.isfinite(verts[..., 0]) & np.isfinite(normals[..., 0])
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(verts[ok].astype(np.float64))
    pc.normals = o3d.utility.Vector3dVector(normals[ok].astype(np.float64))
    return pc
