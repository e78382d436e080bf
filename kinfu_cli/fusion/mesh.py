"""Surface extraction from a TernaryVolume: marching cubes (scikit-image) over known voxels only.

The grid is processed in chunks around blocks that hold per-voxel storage (the only places where a
surface can be), so a 512^3 volume never becomes dense at once. A cube is meshed only when all its
8 corners are known (w > 0), so no surface appears between observed and unknown space.
"""

from __future__ import annotations

import numpy as np
from skimage.measure import marching_cubes

CHUNK = 48  # voxels per chunk edge (chunks without surface blocks are skipped)


def _known_cubes_mask(known: np.ndarray) -> np.ndarray:
    """skimage marches the cube whose maximum corner is (x, y, z) when mask[x, y, z]: require all 8 corners known."""
    m = np.zeros_like(known)
    k = known
    m[1:, 1:, 1:] = (k[1:, 1:, 1:] & k[:-1, 1:, 1:] & k[1:, :-1, 1:] & k[1:, 1:, :-1]
                     & k[:-1, :-1, 1:] & k[:-1, 1:, :-1] & k[1:, :-1, :-1] & k[:-1, :-1, :-1])
    return m


# offsets from a vertex's cube's lowest corner to the voxels searched for a colour: the cube's eight corners and
# the ring around them (4^3 voxels, all within 2 voxels of the vertex along each axis)
_AROUND = np.array([[i, j, k] for i in range(-1, 3) for j in range(-1, 3) for k in range(-1, 3)], dtype=np.int64)
MAX_COLOR_REACH = 2.0  # voxels: the farthest coloured voxel a vertex takes its colour from


def vertex_colors(tc: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Colours (N, 3) uint8 of vertices v (N, 3, voxel units of the dense colour box tc): the nearest voxel's, or,
    when that one was never coloured (black), the nearest coloured voxel within MAX_COLOR_REACH voxels. Fusion
    colours only voxels within about a voxel of the surface ALONG THE CAMERA RAY, so on a surface seen at a
    grazing angle (a floor far away) that band is a fraction of a voxel thick across the surface, and the voxel
    nearest to a vertex often lies outside it: before, 11 % of the sample recording's mesh and 27 % of the real
    tabletop box's came out black."""
    top = np.array(tc.shape[:3]) - 1
    idx = np.clip(np.rint(v).astype(np.int64), 0, top)
    out = tc[idx[:, 0], idx[:, 1], idx[:, 2]]
    black = np.flatnonzero(~out.any(axis=1))
    for part in np.array_split(black, max(1, len(black) // 65536)):  # bounded temporaries
        if len(part) == 0:
            continue
        vb = v[part]
        near = np.floor(vb).astype(np.int64)[:, None, :] + _AROUND[None]  # (n, 64, 3)
        inside = np.all((near >= 0) & (near <= top), axis=2)
        near = np.clip(near, 0, top)
        cc = tc[near[..., 0], near[..., 1], near[..., 2]]  # (n, 64, 3)
        d2 = np.sum((near - vb[:, None, :]) ** 2, axis=2)
        d2[~(cc.any(axis=2) & inside) | (d2 > MAX_COLOR_REACH ** 2)] = np.inf
        best = np.argmin(d2, axis=1)
        found = np.isfinite(d2[np.arange(len(part)), best])
        out[part[found]] = cc[np.flatnonzero(found), best[found]]  # none within reach: stays black
    return out


def surface_arrays(vol, lo=None, hi=None):
    """Vertices (N, 3) world, faces (M, 3), vertex normals (N, 3, pointing into empty space) and colours
    (N, 3) uint8 of the v = 0 surface inside the voxel box [lo, hi) (default: everywhere)."""
    empty = (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    sblocks = vol.surface_blocks()
    ib = np.argwhere(sblocks)
    if ib.size == 0:
        return empty
    blo = ib.min(axis=0) * 8
    bhi = np.minimum((ib.max(axis=0) + 1) * 8, vol.shape)
    if lo is not None:
        blo = np.maximum(blo, np.asarray(lo, np.int64))
    if hi is not None:
        bhi = np.minimum(bhi, np.asarray(hi, np.int64))
    if np.any(bhi - blo < 2):
        return empty
    B = 8
    verts_all, faces_all, norms_all, cols_all = [], [], [], []
    nv = 0
    for x0 in range(int(blo[0]), int(bhi[0]) - 1, CHUNK):
        for y0 in range(int(blo[1]), int(bhi[1]) - 1, CHUNK):
            for z0 in range(int(blo[2]), int(bhi[2]) - 1, CHUNK):
                c_lo = np.array([x0, y0, z0])
                c_hi = np.minimum(c_lo + CHUNK + 1, bhi)
                b0 = c_lo // B
                b1 = (c_hi + B - 1) // B
                if not np.any(sblocks[b0[0]:b1[0], b0[1]:b1[1], b0[2]:b1[2]]):
                    continue
                tv, tw, tc = vol.tsdf_weights(c_lo, c_hi, color=True)
                known = tw > 0
                mask = _known_cubes_mask(known)
                if not mask.any():
                    continue
                if not ((tv[known] > 0).any() and (tv[known] <= 0).any()):
                    continue
                try:
                    v, f, n, _ = marching_cubes(tv, level=0.0, mask=mask, allow_degenerate=False)
                except (RuntimeError, ValueError):
                    continue
                if len(f) == 0:
                    continue
                if tc.shape[0]:
                    cols_all.append(vertex_colors(tc, v))
                verts_all.append(vol.origin + (c_lo + v + 0.5) * vol.voxel_size)
                faces_all.append(f + nv)
                # skimage's normals follow the descending gradient; ours point up the gradient (into empty space)
                norms_all.append(-n)
                nv += len(v)
    if not verts_all:
        return empty
    verts = np.concatenate(verts_all)
    faces = np.concatenate(faces_all)
    norms = np.concatenate(norms_all)
    cols = np.concatenate(cols_all) if cols_all else np.full((len(verts), 3), 180, np.uint8)
    return verts, faces, norms, cols


def extract_mesh(vol, lo=None, hi=None):
    """open3d TriangleMesh (vertex colours and normals) of the volume's surface, seams between chunks merged."""
    import open3d as o3d  # heavy: only when a mesh is made

    v, f, n, c = surface_arrays(vol, lo, hi)
    mesh = o3d.geometry.TriangleMesh()
    if len(f) == 0:
        return mesh
    # skimage's winding already makes the faces' right-hand normals point into empty space (up the TSDF
    # gradient), the same way as the vertex normals: keep it, so viewers show the outside of surfaces
    mesh.vertices = o3d.utility.Vector3dVector(v)
    mesh.triangles = o3d.utility.Vector3iVector(f.astype(np.int32))
    mesh.vertex_normals = o3d.utility.Vector3dVector(n)
    mesh.vertex_colors = o3d.utility.Vector3dVector(c.astype(np.float64) / 255.0)
    mesh.remove_duplicated_vertices()
    mesh.remove_degenerate_triangles()
    mesh.remove_unreferenced_vertices()
    return mesh


def mesh_cloud(mesh):
    """open3d PointCloud of a mesh's vertices with their colours and normals (pointing into empty space): the
    surface points, as KinFu's ExtractSurfacePts."""
    import open3d as o3d  # heavy: only when a cloud is made

    cloud = o3d.geometry.PointCloud()
    cloud.points, cloud.colors, cloud.normals = mesh.vertices, mesh.vertex_colors, mesh.vertex_normals
    return cloud
