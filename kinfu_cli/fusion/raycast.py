"""Ray-cast maps of a TernaryVolume from a pose: depth, normal and vertex maps (tracking, report, NBV).

The kernel lives in kernels.raycast_kernel; TernaryVolume.raycast calls it. Helpers here turn the
maps into what the tracker and the report need.
"""

from __future__ import annotations

import numpy as np

from kinfu_cli.core.camera import scaled_intrinsics


def raycast_maps(volume, K: np.ndarray, width: int, height: int, T_world_camera: np.ndarray):
    """dict with depth (H, W) z metres (0 = miss), normals and vertices (H, W, 3) in world coordinates (NaN
    = miss) and state (H, W) int8 (1 surface hit, 0 unknown met, -1 left through empty space)."""
    depth, normals, verts, state = volume.raycast(K, width, height, T_world_camera, return_state=True)
    return {"depth": depth, "normals": normals, "vertices": verts, "state": state}


def model_cloud(volume, K: np.ndarray, width: int, height: int, T_world_camera: np.ndarray, scale: float = 0.5):
    """open3d PointCloud (world) with normals of the model surface seen from a pose, ray cast at `scale` of
    the image size: the target of frame-to-model ICP."""
    import open3d as o3d

    w = max(8, int(round(width * scale)))
    h = max(8, int(round(height * scale)))
    _, normals, verts = volume.raycast(scaled_intrinsics(K, w / width), w, h, T_world_camera)
    ok = np.isfinite(verts[..., 0]) & np.isfinite(normals[..., 0])
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(verts[ok].astype(np.float64))
    pc.normals = o3d.utility.Vector3dVector(normals[ok].astype(np.float64))
    return pc


def depth_to_png(depth: np.ndarray, path, max_depth: float | None = None) -> None:
    """Write a ray-cast depth map as a grey PNG (near = bright, miss = black), atomically."""
    import cv2

    from kinfu_cli.core.atomic import atomic_path

    d = np.asarray(depth, dtype=np.float32)
    top = float(max_depth) if max_depth else float(d.max() or 1.0)
    img = np.where(d > 0, 255 - np.clip(d / top * 230, 0, 230), 0).astype(np.uint8)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), img):
            raise OSError(f"could not write {path}")
