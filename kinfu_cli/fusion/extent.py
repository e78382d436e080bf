"""Grid size 'auto': a box around what the recording observes, from a quick first pass, within a memory budget.

`survey(views)` back-projects a sparse pixel subset of some frames at their poses; `auto_grid(...)` turns the
points (and camera positions) into a grid: box plus margin, voxel size as given (default KinFu's 3 m / 512),
and, when the grid's worst-case memory exceeds the budget, a coarser voxel (voxel size not given) or the
densest sub-box (voxel size given). `face_contacts(labels)` counts occupied voxels on each face of a grid:
a scene the grid cuts off.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.fusion.placement import backproject
from kinfu_cli.core.memory import available_bytes
from kinfu_cli.fusion.volume import worst_case_bytes

# voxel edge when none is given: KinFu's 3 m grid of 512 voxels
DEFAULT_VOXEL = 3.0 / 512
# the first pass decodes at most this many frames (spread evenly over the selection) and every 8th pixel of
# each in both directions, plus the farthest pixel of each 8 x 8 tile (depth may jump between sampled pixels):
# a few seconds for any recording, and a box that differs from the full one by less than the margin
SURVEY_FRAMES = 120
SURVEY_STRIDE = 8
# memory budget when none is given: half of the memory available now (the read-out copies the labels, and
# open3d meshing needs room), at most 2 GiB (2.5 times the worst case of KinFu's 512^3 grid with colour)
DEFAULT_BUDGET_FRACTION = 0.5
DEFAULT_BUDGET_BYTES = 2 * 1024**3
# a budget given in GiB: from about a MiB (less holds no grid a frame fits in: a 32^3 grid with colour needs ~0.4 MiB)
# to about a PiB (more is no budget on any machine; 1e308 GiB overflowed the byte count)
MIN_BUDGET_GIB = 0.001
MAX_BUDGET_GIB = 1e6
FACES = ("x-", "x+", "y-", "y+", "z-", "z+")
# a face cuts the scene when its occupied voxels could form a line of surface this long (and at least
# CUT_MIN_VOXELS): fewer are speckle, flying pixels at the far range that the survey's sparse pixels miss (real
# 7-Scenes and tabletop frames leave 1-3 such voxels on the auto grid's faces; a grid that cuts a table or a
# wall leaves hundreds)
CUT_LINE_M = 0.05
CUT_MIN_VOXELS = 3


@dataclass
class AutoGrid:
    """A grid chosen from the observed box: origin, size (m per axis), voxel size and how it was chosen."""

    origin: np.ndarray
    size: tuple[float, float, float]
    voxel_size: float
    shape: tuple[int, int, int]
    box_min: np.ndarray  # observed points and camera positions, before the margin
    box_max: np.ndarray
    frames: int  # frames surveyed
    points: int
    budget_bytes: int
    worst_case_bytes: int
    capped: str = ""  # "" or what the budget changed

    def as_dict(self) -> dict:
        return {"mode": "auto", "observed_min": np.round(self.box_min, 4).tolist(),
                "observed_max": np.round(self.box_max, 4).tolist(), "frames_surveyed": self.frames,
                "points_surveyed": self.points, "budget_GiB": round(self.budget_bytes / 1024**3, 3),
                "worst_case_GiB": round(self.worst_case_bytes / 1024**3, 3), "capped": self.capped}

    def note(self) -> str:
        nx, ny, nz = self.shape
        sx, sy, sz = self.size
        text = (f"grid auto-sized to {sx:.2f} x {sy:.2f} x {sz:.2f} m ({nx}x{ny}x{nz} voxels of "
                f"{self.voxel_size * 1000:.2f} mm) from {self.frames} frame(s); worst-case memory "
                f"{self.worst_case_bytes / 1024**3:.2f} GiB of a {self.budget_bytes / 1024**3:.2f} GiB budget")
        return text + (f"; {self.capped}" if self.capped else "")


@dataclass
class Survey:
    """What the first pass saw: world points, camera positions, frames, and the largest gap between sampled
    pixels (m, at the farthest reading): how far the scene may reach beyond the sampled points."""

    points: np.ndarray
    cameras: np.ndarray
    frames: int
    spacing: float


def survey(views: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]], min_depth: float,
           max_depth: float) -> Survey:
    """World points of every SURVEY_STRIDE-th valid pixel of (depth, K, T_world_camera) views, and of the farthest
    valid pixel of each SURVEY_STRIDE x SURVEY_STRIDE tile."""
    pts, cams, spacing = [], [], 0.0
    for depth, K, T in views:
        p = backproject(depth, K, T, stride=SURVEY_STRIDE, min_depth=min_depth, max_depth=max_depth)
        far = farthest_per_block(depth, K, T, SURVEY_STRIDE, min_depth, max_depth)
        p = np.concatenate([p, far]) if len(far) else p
        pts.append(p)
        cams.append(np.asarray(T, dtype=np.float64)[:3, 3])
        if len(p):
            far = float(np.max(np.linalg.norm(p - cams[-1], axis=1)))
            spacing = max(spacing, SURVEY_STRIDE * far / min(K[0, 0], K[1, 1]))
    points = np.concatenate(pts) if pts else np.zeros((0, 3))
    return Survey(points, np.array(cams).reshape(-1, 3), len(cams), spacing)


def farthest_per_block(depth: np.ndarray, K: np.ndarray, T: np.ndarray, block: int, min_depth: float,
                       max_depth: float) -> np.ndarray:
    """World points of the farthest in-range pixel of each block x block tile: between two sampled pixels a
    surface seen at a grazing angle, or through a gap, reaches deeper than either (the 7-Scenes kitchen's far
    side went 10 cm beyond the sampled points, out of the grid's margin)."""
    d = np.asarray(depth, dtype=np.float64)
    h, w = (d.shape[0] // block) * block, (d.shape[1] // block) * block
    tiles = d[:h, :w].reshape(h // block, block, w // block, block).transpose(0, 2, 1, 3).reshape(
        h // block, w // block, block * block)
    ok = np.isfinite(tiles) & (tiles > min_depth) & (tiles <= max_depth) & (tiles > 0)
    k = np.argmax(np.where(ok, tiles, -1.0), axis=2)
    has = ok.any(axis=2)
    bi, bj = np.nonzero(has)
    kk = k[bi, bj]
    v, u = bi * block + kk // block, bj * block + kk % block
    z = d[v, u]
    pc = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
    return pc @ np.asarray(T)[:3, :3].T + np.asarray(T)[:3, 3]


def budget_bytes(max_memory_gib: float | None) -> int:
    """The memory budget: max_memory_gib when given, else DEFAULT_BUDGET_FRACTION of the available memory,
    at most DEFAULT_BUDGET_BYTES."""
    if max_memory_gib is None:
        return int(min(DEFAULT_BUDGET_BYTES, DEFAULT_BUDGET_FRACTION * available_bytes()))
    if not (MIN_BUDGET_GIB <= max_memory_gib <= MAX_BUDGET_GIB):  # NaN fails too
        raise ConfigError(f"expected a number of GiB from {MIN_BUDGET_GIB:g} to {MAX_BUDGET_GIB:g}, got "
                          f"{max_memory_gib:g}", parameter="max_memory")
    return int(max_memory_gib * 1024**3)


def auto_grid(seen: Survey, *, voxel_size: float | None, resolution: int | tuple | None, truncation: float,
              color: bool, budget: int, origin: tuple | None = None, grow: float = 0.0) -> AutoGrid:
    """The grid around the surveyed points and camera positions.

    Box: their min / max per axis, grown by `grow` times its extent on each side (for a camera path not known
    yet), plus a margin: the truncation distance (occupied voxels reach that far behind a surface), the survey's
    pixel spacing (the scene reaches that far beyond the sampled points) and two voxels (rounding), so that the
    outermost occupied voxels stay off the faces. With `origin` the box starts there.
    Voxel: voxel_size; else with `resolution` (N or nx,ny,nz) the smallest voxel giving that many voxels per
    axis over the box; else DEFAULT_VOXEL. Budget (bytes of the worst case, every block a surface): above it a
    default voxel grows until the grid fits; a given voxel size keeps its value and the box shrinks around the
    densest region of the points.
    """
    points, cameras = seen.points, seen.cameras
    if len(points) == 0:
        raise VolumeError("cannot size the grid: the frames have no valid depth in range (give the grid size)",
                          parameter="size")
    every = np.concatenate([points, cameras]) if len(cameras) else points
    lo, hi = every.min(axis=0), every.max(axis=0)
    ext = hi - lo
    lo, hi = lo - grow * ext, hi + grow * ext
    capped = ""
    if resolution is not None:
        res = np.broadcast_to(np.asarray(resolution, dtype=np.float64), (3,))
        # the box and its margin spread over the voxels of each axis
        vs = float(np.max((hi - lo + 2 * (truncation + seen.spacing)) / np.maximum(res - 4, res / 2)))
    else:
        vs = float(voxel_size) if voxel_size is not None else DEFAULT_VOXEL
    margin = truncation + seen.spacing + 2 * vs
    if origin is not None:
        lo0 = np.asarray(origin, dtype=np.float64)
        if np.any(hi + margin <= lo0):
            raise ConfigError(f"the observed scene (up to {np.round(hi, 2).tolist()}) lies below the origin on "
                              f"some axis; give the size too", parameter="origin")
    else:
        lo0 = lo - margin
    size = hi + margin - lo0
    if resolution is not None:
        shape = np.broadcast_to(np.asarray(resolution, dtype=np.int64), (3,))
        size = shape * vs
        if origin is None:
            lo0 = 0.5 * (lo + hi) - 0.5 * size
    else:
        shape = np.ceil(size / vs - 1e-9).astype(np.int64)
        need = worst_case_bytes(shape, color)
        if need > budget and voxel_size is None:
            vs0 = vs
            while need > budget:  # a few steps: the first one nearly fits
                vs *= max(1.01, (need / budget) ** (1 / 3))
                margin = truncation + seen.spacing + 2 * vs
                lo0 = lo - margin if origin is None else lo0
                size = hi + margin - lo0
                shape = np.ceil(size / vs - 1e-9).astype(np.int64)
                need = worst_case_bytes(shape, color)
            capped = f"voxel coarsened from {vs0 * 1000:.2f} to {vs * 1000:.2f} mm to fit the budget"
        elif need > budget:
            keep = (budget / need) ** (1 / 3)
            new_size = np.maximum(size * keep, vs)
            lo0 = _densest_window(points, lo0, size, new_size) if origin is None else lo0
            size = new_size
            shape = np.maximum(1, np.floor(size / vs)).astype(np.int64)
            while worst_case_bytes(shape, color) > budget:
                shape = np.maximum(1, shape - 8)
            size = shape * vs
            capped = (f"box cropped from {_fmt(hi + margin - (lo - margin))} m to the densest "
                      f"{_fmt(size)} m to fit the budget at the given voxel size")
    shape = tuple(int(x) for x in shape)
    return AutoGrid(origin=np.asarray(lo0, dtype=np.float64), size=tuple(float(s) for s in np.asarray(shape) * vs),
                    voxel_size=vs, shape=shape, box_min=lo, box_max=hi, frames=seen.frames, points=len(points),
                    budget_bytes=int(budget), worst_case_bytes=worst_case_bytes(shape, color), capped=capped)


def _densest_window(points: np.ndarray, lo: np.ndarray, size: np.ndarray, new_size: np.ndarray) -> np.ndarray:
    """Per axis, the start of the window of length new_size inside [lo, lo + size] holding the most points
    (histograms at 1 cm)."""
    out = np.array(lo, dtype=np.float64)
    for a in range(3):
        n = max(1, int(np.ceil(size[a] / 0.01)))
        hist, _ = np.histogram(points[:, a], bins=n, range=(lo[a], lo[a] + size[a]))
        w = max(1, min(n, int(round(new_size[a] / 0.01))))
        c = np.concatenate([[0], np.cumsum(hist)])
        best = int(np.argmax(c[w:] - c[:-w]))
        out[a] = lo[a] + best * 0.01
    return out


def _fmt(v) -> str:
    return " x ".join(f"{x:.2f}" for x in v)


def cut_faces(faces: dict[str, int], voxel_size: float) -> dict[str, int]:
    """The faces of `face_contacts` whose occupied voxels are enough to be a cut scene, not speckle."""
    least = max(CUT_MIN_VOXELS, int(np.ceil(CUT_LINE_M / voxel_size - 1e-9)))
    return {f: n for f, n in faces.items() if n >= least}


def face_contacts(labels: np.ndarray) -> dict[str, int]:
    """Occupied voxels (label 1) in the outermost layer of each face of the grid: {"x-": n, ...}."""
    layers = (labels[0], labels[-1], labels[:, 0], labels[:, -1], labels[:, :, 0], labels[:, :, -1])
    return {face: int(np.count_nonzero(layer == 1)) for face, layer in zip(FACES, layers)}
