"""Reconstruction error of a fused surface against the true mesh: accuracy, completeness, volume coverage.

Both directions, as the usual accuracy / completeness metrics:

- accuracy: distance from every reconstructed mesh vertex (marching-cubes vertices are spaced about one voxel apart)
  to the true mesh, with open3d's `RaycastingScene.compute_distance` (one vectorised call). Vertices outside the
  evaluation region (the box around the observed true surface, grown by `region_margin`) are left out and counted.
- completeness: the true surface is sampled uniformly (one point per `spacing`^2 of area, area-weighted over the
  triangles). The region the camera observed is the set of samples that are *visible* from at least one true
  camera pose of the recording (`camera_poses.txt`): the sample projects into the image, lies within the sensor's
  range, and its depth agrees (within `visibility_tolerance`) with the true mesh's depth rendered at that pixel (a
  z-buffer test, one open3d ray cast per frame, back faces never count). Only samples inside the reconstruction's
  extent count: its volume grid, or for a bare mesh its bounding box grown by `region_margin`. Completeness = share
  of those samples within `threshold` (default 1 cm) of the reconstruction; precision = share of the evaluated
  vertices within `threshold` of the truth; F-score their harmonic mean.
- volume coverage (when the volume is known): counts of unknown / empty / occupied voxels and the share of the true
  surface (visible samples, and all samples inside the grid) whose voxel is known (w > 0).

Which poses belong to a state: "before" = the initial-scan frames (`frames.scan` of changes.json), "after" = all
frames (the after-change views look at the changed region; the rest of the table is the same in both states). When
the input is a `kinfu fuse` folder whose report.json records a time window (a start and/or end time), only the poses
inside it count: the observed region is what the fused frames saw.

`evaluate_fusion` is the driver: paths in, a `FusionEvaluation` (the results document and what it was computed
from) out. Tables are formatted by `evaluation.tables`, the error-coloured mesh is written by `report`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d
from numba import njit, prange
from scipy.spatial import cKDTree

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, RecordingError, VolumeError
from kinfu_cli.core.grid import UNKNOWN
from kinfu_cli.core.progress import progress
from kinfu_cli.core.volume_file import report_json_of
from kinfu_cli.io.messages import c_stderr_silenced
from kinfu_cli.io.mesh_faces import faces_outside_vertices
from kinfu_cli.io.ply_size import ply_cut_short
from kinfu_cli.evaluation.object_measures import PAPER_TABLE_1, ObjectMeasuresResult, object_measures
from kinfu_cli.fusion.volume import TernaryVolume, load_volume
from kinfu_cli.sim.sampling import MAX_SAMPLES, sample_surface, surface_area
from kinfu_cli.sim.scenario import GroundTruth, load_ground_truth
from kinfu_cli.sim.sensor import ideal_depth

DEFAULT_THRESHOLD = 0.01  # m: completeness / precision distance
DEFAULT_SPACING = 0.005  # m: true-surface sample spacing
# more than this share of the true surface the cameras saw lying outside the reconstruction's extent is a warning:
# completeness counts only what lies inside, and the whole view's is about completeness x (1 - share) (the mesh
# cannot reach beyond its grid), so a grid that crops the scene scores up to `share` better (a 0.5 m corner of a
# synth scene: 95 % left out, completeness 0.91 against 0.77 with the whole scene); scene-sized grids (auto, the
# sample data) leave 0 % out
SEEN_OUTSIDE_WARN = 0.05
STATES = ("after", "before")
MESH_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".gltf", ".glb")


# ---------------------------------------------------------------------------------------------- statistics
@dataclass
class DistanceStats:
    """Summary of a set of distances (metres)."""

    count: int
    mean: float
    median: float
    rms: float
    p95: float
    max: float

    @classmethod
    def of(cls, d: np.ndarray) -> "DistanceStats":
        d = np.asarray(d, dtype=np.float64).ravel()
        if d.size == 0:
            nan = float("nan")
            return cls(0, nan, nan, nan, nan, nan)
        return cls(int(d.size), float(d.mean()), float(np.median(d)), float(np.sqrt(np.mean(d * d))),
                   float(np.percentile(d, 95)), float(d.max()))

    def to_json(self) -> dict:
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in self.__dict__.items()}


# ---------------------------------------------------------------------------------------------- inputs
@dataclass
class Reconstruction:
    """What `kinfu eval fusion` scores: a mesh (vertices, triangles; triangles may be empty for a cloud) and,
    when the input is a `kinfu fuse` folder holding volume.npz, the volume."""

    vertices: np.ndarray
    triangles: np.ndarray
    source: Path
    volume: TernaryVolume | None = None
    volume_path: Path | None = None

    @property
    def is_cloud(self) -> bool:
        return len(self.triangles) == 0


def read_mesh_arrays(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (N, 3) float64, triangles (M, 3) int64) of a mesh or point-cloud file; VolumeError when it is
    missing, unreadable, has no vertices or faces that index past them."""
    path = Path(path)
    if not path.is_file():
        raise VolumeError(f"{path}: no such mesh file")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise VolumeError(f"{path}: expected a mesh file ({', '.join(MESH_SUFFIXES)}) or a `kinfu fuse` output folder")
    if path.suffix.lower() == ".ply" and (short := ply_cut_short(path)) is not None:
        raise VolumeError(f"{path}: PLY file cut short ({short}): truncated or damaged")
    # we report problems ourselves (RPly writes its own lines on a damaged PLY, whatever the verbosity)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error), c_stderr_silenced():
        mesh = o3d.io.read_triangle_mesh(str(path))
        v = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.triangles, dtype=np.int64).reshape(-1, 3)
        if len(v) == 0 and path.suffix.lower() == ".ply" and path.stat().st_size > 0:
            v = np.asarray(o3d.io.read_point_cloud(str(path)).points, dtype=np.float64)
    if len(v) == 0:
        raise VolumeError(f"{path}: mesh has no vertices (empty reconstruction or not a mesh file)")
    if not np.all(np.isfinite(v)):
        raise VolumeError(f"{path}: mesh has non-finite vertex coordinates")
    if (outside := faces_outside_vertices(len(v), f)) is not None:
        raise VolumeError(f"{path}: {outside}")
    return v, f


def load_reconstruction(path: str | os.PathLike, use_volume: bool = True) -> Reconstruction:
    """A mesh file, or a `kinfu fuse` output folder (mesh.ply, and volume.npz when present)."""
    path = Path(path)
    if path.is_dir():
        mesh_path = path / "mesh.ply"
        if not mesh_path.exists():
            raise VolumeError(f"{path}: no mesh.ply in this folder (expected a `kinfu fuse` output folder or a "
                              f"mesh file)")
        v, f = read_mesh_arrays(mesh_path)
        vol, vol_path = None, None
        if use_volume and (path / "volume.npz").exists():
            vol_path = path / "volume.npz"
            vol = load_volume(vol_path)
        return Reconstruction(v, f, mesh_path, vol, vol_path)
    if not path.exists():
        raise VolumeError(f"{path}: no such mesh file or `kinfu fuse` output folder")
    v, f = read_mesh_arrays(path)
    return Reconstruction(v, f, path)


def state_frames(gt: GroundTruth, state: str, window: tuple | None = None) -> np.ndarray:
    """Indices of the ground-truth camera poses that saw the scene in `state` (see module docstring), and, with
    window = (start_s, end_s) in seconds after the recording start (either may be None), only those whose stamp
    is inside it (the frames a time-limited `kinfu fuse` run used)."""
    if state not in STATES:
        raise ConfigError(f"expected one of {', '.join(STATES)}, got {state!r}", parameter="state")
    n = len(gt.poses)
    if n == 0:
        raise RecordingError(f"{gt.folder}/camera_poses.txt: no camera poses")
    scan = gt.info.get("frames", {}).get("scan")
    idx = np.arange(n)
    if state == "before":
        n_scan = n if scan is None else int(scan)
        idx = idx[: min(max(n_scan, 1), n)]
    if window is not None:
        t = (gt.stamps_ns[idx] - int(gt.info.get("t0_ns", gt.stamps_ns[0]))) * 1e-9
        lo, hi = window
        keep = np.ones(len(idx), dtype=bool)
        if lo is not None:
            keep &= t >= float(lo) - 1e-6
        if hi is not None:
            keep &= t <= float(hi) + 1e-6
        idx = idx[keep]
    return idx


def fused_window(report: dict | None) -> tuple | None:
    """(start_s, end_s) of the frames a `kinfu fuse` run used (its report.json "frames"), or None."""
    fr = (report or {}).get("frames") or {}
    fr = fr if isinstance(fr, dict) else {}  # a hand-edited report: ignore what is not a kinfu fuse report's
    lo, hi = (v if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None
              for v in (fr.get("start_s"), fr.get("end_s")))
    if lo is None and hi is None:
        return None
    return lo, hi


# ---------------------------------------------------------------------------------------------- geometry
def mesh_scene(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
    """An open3d RaycastingScene of a mesh given as arrays (distances, visibility)."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32)))
    return scene


def point_to_mesh_distance(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray, scene=None
                           ) -> np.ndarray:
    """Unsigned distance (N,) from each point to the mesh surface (open3d RaycastingScene.compute_distance)."""
    pts = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    if len(pts) == 0:
        return np.zeros(0)
    scene = scene if scene is not None else mesh_scene(vertices, triangles)
    return scene.compute_distance(o3d.core.Tensor(pts)).numpy().astype(np.float64)


def distance_to_reconstruction(points: np.ndarray, rec: Reconstruction) -> np.ndarray:
    """Distance of points to the reconstructed surface (to its triangles; to its points for a cloud)."""
    if rec.is_cloud:
        return cKDTree(rec.vertices).query(np.asarray(points, dtype=np.float64), workers=-1)[0]
    return point_to_mesh_distance(points, rec.vertices, rec.triangles)


def visible_mask(points: np.ndarray, normals: np.ndarray, scene, poses: np.ndarray, K: np.ndarray, width: int,
                 height: int, min_depth: float = 0.3, max_depth: float = 4.0, tolerance: float = 0.005,
                 chunk: int = 16) -> np.ndarray:
    """Which surface points (on the mesh held by `scene`, with their outward normals) are seen from at least one
    pose: facing the camera, projecting into the image with depth in [min_depth, max_depth], and not hidden: the
    true depth rendered at their pixel is >= their depth - (tolerance + the depth change across one pixel on a
    surface that steep, capped at 10 pixels' worth). Depth images are rendered `chunk` poses at a time (open3d),
    the per-point tests run in a numba kernel."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    K = np.asarray(K, dtype=np.float64)
    seen = np.zeros(len(pts), dtype=np.bool_)
    pix = 1.0 / min(K[0, 0], K[1, 1])
    for c0 in range(0, len(poses), max(1, int(chunk))):
        Ts = poses[c0:c0 + max(1, int(chunk))]
        depths = np.stack([ideal_depth(scene, K, width, height, T) for T in Ts]).astype(np.float32)
        _visible_kernel(pts, nrm, np.ascontiguousarray(Ts[:, :3, :3]), np.ascontiguousarray(Ts[:, :3, 3]), depths,
                        float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]), float(min_depth),
                        float(max_depth), float(tolerance), pix, seen)
    return seen


@njit(cache=True, parallel=True)
def _visible_kernel(pts, nrm, Rs, ts, depths, fx, fy, cx, cy, min_depth, max_depth, tol, pix, seen):  # pragma: no cover
    n = pts.shape[0]
    nf, h, w = depths.shape
    for i in prange(n):
        if seen[i]:
            continue
        for f in range(nf):
            dx = pts[i, 0] - ts[f, 0]
            dy = pts[i, 1] - ts[f, 1]
            dz = pts[i, 2] - ts[f, 2]
            zc = dx * Rs[f, 0, 2] + dy * Rs[f, 1, 2] + dz * Rs[f, 2, 2]
            if zc < min_depth or zc > max_depth:
                continue
            cosv = -(dx * nrm[i, 0] + dy * nrm[i, 1] + dz * nrm[i, 2])  # normal . (camera - point)
            if cosv <= 0.0:
                continue
            xc = dx * Rs[f, 0, 0] + dy * Rs[f, 1, 0] + dz * Rs[f, 2, 0]
            yc = dx * Rs[f, 0, 1] + dy * Rs[f, 1, 1] + dz * Rs[f, 2, 1]
            u = int(math.floor(fx * xc / zc + cx + 0.5))
            v = int(math.floor(fy * yc / zc + cy + 0.5))
            if u < 0 or u >= w or v < 0 or v >= h:
                continue
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            cos = min(max(cosv / dist, 1e-3), 1.0)
            slope = min(math.sqrt(max(1.0 - cos * cos, 0.0)) / cos, 10.0)
            if depths[f, v, u] >= zc - (tol + pix * zc * slope):
                seen[i] = True
                break


def visible_mask_exact(points: np.ndarray, normals: np.ndarray, scene, poses: np.ndarray, K: np.ndarray,
                       width: int, height: int, min_depth: float = 0.3, max_depth: float = 4.0,
                       stop_short: float = 0.002) -> np.ndarray:
    """Reference for visible_mask: the same image / range / facing tests, then one ray from the camera centre to
    every candidate point (open3d cast_rays); visible when nothing is hit before `stop_short` of the point.
    Exact but casts a ray per point and pose (see benchmarks/bench_eval_fusion.py)."""
    pts = np.asarray(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    seen = np.zeros(len(pts), dtype=bool)
    for T in np.asarray(poses, dtype=np.float64):
        d = pts - T[:3, 3]
        pc = d @ T[:3, :3]
        z = pc[:, 2]
        zs = np.where(z > 0, z, 1.0)
        u = np.rint(K[0, 0] * pc[:, 0] / zs + K[0, 2])
        v = np.rint(K[1, 1] * pc[:, 1] / zs + K[1, 2])
        ok = (z >= min_depth) & (z <= max_depth) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
        ok &= np.einsum("ij,ij->i", nrm, -d) > 0
        idx = np.flatnonzero(ok)
        if idx.size == 0:
            continue
        rays = np.hstack([np.broadcast_to(T[:3, 3], (idx.size, 3)), d[idx]]).astype(np.float32)
        t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        seen[idx[t_hit >= 1.0 - stop_short / np.linalg.norm(d[idx], axis=1)]] = True
    return seen


# ---------------------------------------------------------------------------------------------- scoring
@dataclass
class ReconstructionScore:
    accuracy: DistanceStats
    completeness_distances: DistanceStats
    threshold: float
    precision: float  # share of evaluated reconstructed vertices within threshold of the truth
    completeness: float  # share of observed true-surface samples within threshold of the reconstruction
    fscore: float
    vertices_total: int
    vertices_outside_region: int
    samples_observed: int
    samples_total: int
    spacing: float
    region: tuple
    frames: int
    coverage: dict | None = None
    notes: list = field(default_factory=list)
    vertex_distances: np.ndarray | None = field(default=None, repr=False)  # per vertex, NaN outside the region
    samples_visible_outside: int = 0  # visible true-surface samples outside the extent (not in completeness)

    def to_json(self) -> dict:
        visible = self.samples_observed + self.samples_visible_outside
        out = {"accuracy": self.accuracy.to_json(), "completeness_distances": self.completeness_distances.to_json(),
               "threshold": self.threshold, "precision": self.precision, "completeness": self.completeness,
               "fscore": self.fscore, "vertices_total": self.vertices_total,
               "vertices_outside_region": self.vertices_outside_region, "samples_observed": self.samples_observed,
               "samples_total": self.samples_total, "samples_visible_outside": self.samples_visible_outside,
               "visible_share_outside": self.samples_visible_outside / visible if visible else None,
               "spacing": self.spacing,
               "region": {"min": list(self.region[0]), "max": list(self.region[1])}, "frames": self.frames,
               "observed_region": "true-surface samples visible (z-buffer test) from the ground-truth camera poses "
                                  "of the state, within the sensor range, inside "
                                  + ("the volume grid" if self.coverage else "the reconstruction's bounding box "
                                     "(grown by the region margin)")}
        if self.coverage is not None:
            out["volume"] = self.coverage
        if self.notes:
            out["notes"] = list(self.notes)
        return out


def volume_coverage(volume: TernaryVolume, samples_visible: np.ndarray, samples_in_grid: np.ndarray) -> dict:
    """Label counts of the volume and the share of true-surface samples whose voxel is known (w > 0)."""
    grid = volume.ternary_grid()
    counts = grid.counts()

    def known_share(p: np.ndarray) -> float | None:
        if len(p) == 0:
            return None
        idx = grid.index_of(p)
        idx = np.clip(idx, 0, np.array(grid.shape) - 1)
        return float(np.mean(grid.labels[idx[:, 0], idx[:, 1], idx[:, 2]] != UNKNOWN))

    total = int(sum(counts.values()))
    return {"shape": list(grid.shape), "voxel_size": grid.voxel_size, "origin": grid.origin.tolist(),
            "counts": counts, "unknown_share": counts["unknown"] / total if total else None,
            "visible_surface_known_share": known_share(samples_visible),
            "surface_in_grid_known_share": known_share(samples_in_grid),
            "surface_samples_in_grid": int(len(samples_in_grid))}


def _in_box(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.all((p >= lo) & (p <= hi), axis=1)


@dataclass
class ObservedSurface:
    """True-surface samples of one state: `in_bounds` (the samples inside `bounds`), `seen` (which of them are
    visible from the state's camera poses), how many were drawn in all, and the settings."""

    in_bounds: np.ndarray
    seen: np.ndarray
    total: int
    frames: int
    spacing: float  # the spacing sampled at: the one asked for unless the sampler's count limits changed it
    bounds: tuple
    warnings: list[str] = field(default_factory=list)
    seen_outside: int = 0  # samples visible from the poses but outside bounds (completeness never sees them)

    @property
    def seen_outside_share(self) -> float | None:
        """The share of the visible true surface lying outside bounds (None when none is visible)."""
        visible = self.seen_outside + int(np.count_nonzero(self.seen))
        return self.seen_outside / visible if visible else None

    @property
    def observed(self) -> np.ndarray:
        """The samples the cameras saw (inside bounds)."""
        return self.in_bounds[self.seen]


def observed_surface(gt: GroundTruth, state: str, bounds: tuple, spacing: float = DEFAULT_SPACING,
                     visibility_tolerance: float = 0.005, seed: int = 0, scene=None,
                     frames: np.ndarray | None = None, depth_range: tuple | None = None) -> ObservedSurface:
    """Sample the true `state` mesh uniformly and keep what the state's camera poses (or the given pose indices)
    saw (module docstring) inside the box bounds = (lo, hi). depth_range: the fused volume's (min, max) depth; the
    visible surface left outside the bounds counts only what lies within it (a fusion limited to 1.2 m left the far
    surface out on purpose, not for want of grid)."""
    mesh = gt.mesh(state)
    tv = np.asarray(mesh.vertices, dtype=np.float64)
    tf = np.asarray(mesh.triangles, dtype=np.int64)
    scene = scene if scene is not None else mesh_scene(tv, tf)
    frames = state_frames(gt, state) if frames is None else np.asarray(frames, dtype=np.int64)
    if len(frames) == 0:
        raise RecordingError(f"{gt.folder}: no ground-truth camera pose of the {state} state was used")
    cam = gt.info.get("camera", {})
    samples, normals = sample_surface(tv, tf, spacing, seed=seed, max_samples=MAX_SAMPLES)
    used, warnings = _sampled_spacing(surface_area(tv, tf), len(samples), spacing, state)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    keep = _in_box(samples, lo, hi)
    # every sample, not only those in bounds: how much visible surface the bounds leave out is worth knowing
    near, far = float(cam.get("min_range", 0.3)), float(cam.get("max_range", 4.0))
    seen = visible_mask(samples, normals, scene, gt.poses[frames], gt.K, gt.width, gt.height, near, far,
                        visibility_tolerance)
    seen_outside = int(np.count_nonzero(seen & ~keep))
    if seen_outside and depth_range is not None and (depth_range[0] > near or depth_range[1] < far):
        out = ~keep
        seen_outside = int(np.count_nonzero(visible_mask(
            samples[out], normals[out], scene, gt.poses[frames], gt.K, gt.width, gt.height,
            max(near, float(depth_range[0])), min(far, float(depth_range[1])), visibility_tolerance)))
    return ObservedSurface(samples[keep], seen[keep], int(len(samples)), int(len(frames)), used, (lo, hi), warnings,
                           seen_outside)


def _sampled_spacing(area: float, count: int, spacing: float, state: str) -> tuple[float, list[str]]:
    """The spacing `sample_surface` really sampled at and a warning when it is not `spacing`: it draws at most
    MAX_SAMPLES points and at least one, so a finer or coarser spacing is changed, depending on the mesh's area."""
    wanted = area / spacing / spacing if area > 0 else 0.0  # 1e-300 squared is 0; this is inf, over the limit
    if count == 0 or MAX_SAMPLES >= wanted >= 0.5:  # within the sampler's limits (0.5 rounds to one sample)
        return float(spacing), []
    used = math.sqrt(area / count)
    why = (f"would need {wanted:.3g} samples of the {area:.3g} m^2 true {state} surface, more than the sampler's "
           f"{MAX_SAMPLES}" if wanted > MAX_SAMPLES
           else f"is coarser than the whole {area:.3g} m^2 true {state} surface, which got one sample")
    return used, [f"the true-surface sample spacing {spacing:g} m {why}: it was sampled every {used:.3g} m instead "
                  f"(completeness is measured at that spacing)"]


def coarse_spacing_warnings(spacing: float, threshold: float, observed: int) -> list[str]:
    """A warning when the true surface was sampled (`spacing`: the spacing really used, `_sampled_spacing`)
    farther apart than the `threshold` completeness is measured at: a hole narrower than the spacing can fall
    between the samples, and a few samples make the share jump (spacing 1 m left 6 observed samples of the sample
    scene, completeness 1.0)."""
    if spacing <= threshold:
        return []
    return [f"the true-surface sample spacing {spacing:.3g} m is coarser than the distance threshold {threshold:g} m "
            f"completeness is measured at: it rests on {observed} observed sample{'s' if observed != 1 else ''} and "
            f"misses holes narrower than the spacing; give a spacing of at most the threshold (default "
            f"{DEFAULT_SPACING:g} m)"]


def reconstruction_bounds(rec: Reconstruction, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Where the reconstruction could have surface: its volume's grid, else its bounding box grown by margin."""
    if rec.volume is not None:
        return rec.volume.bounds()
    return rec.vertices.min(axis=0) - margin, rec.vertices.max(axis=0) + margin


def _depth_range(rec: Reconstruction) -> tuple[float, float] | None:
    """The (min, max) depth the reconstruction's volume fused readings within; None without a volume."""
    vol = rec.volume
    return None if vol is None else (float(vol.min_depth), float(vol.max_depth))


def score_reconstruction(rec: Reconstruction, gt: GroundTruth, state: str = "after", threshold: float = DEFAULT_THRESHOLD,
                         spacing: float = DEFAULT_SPACING, region_margin: float = 0.05,
                         visibility_tolerance: float = 0.005, seed: int = 0,
                         surface: ObservedSurface | None = None) -> ReconstructionScore:
    """Accuracy / completeness (and volume coverage when rec has a volume) of rec against gt's `state` mesh.
    surface: a precomputed `observed_surface(gt, state, reconstruction_bounds(rec), ...)` (to score several
    reconstructions of the same extent against one truth)."""
    if not threshold > 0:
        raise ConfigError(f"expected a positive distance in metres, got {threshold}", parameter="threshold")
    if not region_margin >= 0:
        raise ConfigError(f"expected a distance >= 0 m, got {region_margin}", parameter="region_margin")
    mesh = gt.mesh(state)
    tv = np.asarray(mesh.vertices, dtype=np.float64)
    tf = np.asarray(mesh.triangles, dtype=np.int64)
    scene = mesh_scene(tv, tf)
    if surface is None:
        surface = observed_surface(gt, state, reconstruction_bounds(rec, region_margin), spacing,
                                   visibility_tolerance, seed, scene, depth_range=_depth_range(rec))
    observed = surface.observed
    notes = []
    if len(observed) == 0:
        raise RecordingError(f"{gt.folder}: no part of the true {state} surface is visible from the camera poses"
                             + (" inside the volume grid" if rec.volume is not None else " near the reconstruction")
                             + "".join(f" ({w})" for w in surface.warnings))
    lo = observed.min(axis=0) - region_margin
    hi = observed.max(axis=0) + region_margin
    inside = _in_box(rec.vertices, lo, hi)
    if not inside.any():
        raise VolumeError(f"{rec.source}: no reconstructed vertex lies in the observed region "
                          f"{np.round(lo, 2).tolist()}..{np.round(hi, 2).tolist()} (wrong frame or units?)")
    acc = point_to_mesh_distance(rec.vertices[inside], tv, tf, scene)
    comp = distance_to_reconstruction(observed, rec)
    precision = float(np.mean(acc <= threshold))
    completeness = float(np.mean(comp <= threshold))
    f = 2 * precision * completeness / (precision + completeness) if precision + completeness > 0 else 0.0
    if rec.is_cloud:
        notes.append("reconstruction has no triangles: completeness uses distances to its points")
    coverage = None
    if rec.volume is not None:
        coverage = volume_coverage(rec.volume, observed, surface.in_bounds)
    per_vertex = np.full(len(rec.vertices), np.nan)
    per_vertex[inside] = acc
    return ReconstructionScore(DistanceStats.of(acc), DistanceStats.of(comp), float(threshold), precision,
                               completeness, float(f), int(len(rec.vertices)), int(np.count_nonzero(~inside)),
                               int(len(observed)), surface.total, surface.spacing, (lo.tolist(), hi.tolist()),
                               surface.frames, coverage, notes, per_vertex, surface.seen_outside)


# ---------------------------------------------------------------------------------------------- the whole evaluation
POSE_MODE_LABELS = {"forced": "robot kinematics (forced)", "icp": "egomotion (icp)",
                    "hint": "icp, kinematics hint", "topic": "pose topic"}


@dataclass
class FusionEvaluation:
    """What `evaluate_fusion` computed: the results document (`kinfu eval fusion`'s JSON; its
    input.error_mesh is None until a caller writes the error-coloured mesh), the reconstruction and its score
    (per-vertex distances for that mesh)."""

    document: dict
    reconstruction: Reconstruction
    score: ReconstructionScore


def check_fusion_evaluation(*, threshold: float = DEFAULT_THRESHOLD, spacing: float = DEFAULT_SPACING,
                            margin: float = 0.02, min_height: float = 0.005) -> None:
    """The distances of `evaluate_fusion` checked before anything is read (ConfigError naming the first bad one)."""
    for name, val in (("threshold", threshold), ("spacing", spacing)):
        check_number(val, name, 0, 10, low_open=True, unit="m")
    for name, val in (("margin", margin), ("min_height", min_height)):
        check_number(val, name, 0, 10, unit="m")


def evaluate_fusion(path: str | os.PathLike, ground_truth: str | os.PathLike, state: str = "after",
                    threshold: float = DEFAULT_THRESHOLD, spacing: float = DEFAULT_SPACING, margin: float = 0.02,
                    min_height: float = 0.005, footprint: str = "rect", use_volume: bool = True, seed: int = 0,
                    quiet: bool = True) -> FusionEvaluation:
    """Score a `kinfu fuse` output folder (mesh.ply [+ volume.npz]) or a mesh file against a `kinfu synth`
    ground-truth folder (module docstring); quiet: no progress bar."""
    check_fusion_evaluation(threshold=threshold, spacing=spacing, margin=margin, min_height=min_height)
    t0 = time.perf_counter()
    gt = rec = score = measures = surface = frames = None
    report = report_json_of(path)
    window = fused_window(report)
    for step in progress(["ground truth", "reconstruction", "distances", "objects"], total=4, desc="eval fusion",
                         quiet=quiet):
        if step == "ground truth":
            gt = load_ground_truth(ground_truth)
            frames = state_frames(gt, state, window)  # checks the state and the poses before the heavy work
            if len(frames) == 0:
                raise ConfigError(f"{path}: the fused time window {window} s holds no ground-truth camera pose of "
                                  f"the {state} state (compare with the after state?)")
        elif step == "reconstruction":
            rec = load_reconstruction(path, use_volume=use_volume)
        elif step == "distances":
            surface = observed_surface(gt, state, reconstruction_bounds(rec), spacing, seed=seed, frames=frames,
                                       depth_range=_depth_range(rec))
            score = score_reconstruction(rec, gt, state, threshold=threshold, spacing=spacing, seed=seed,
                                         surface=surface)
        else:
            measures = object_measures(rec.vertices, gt, state, margin=margin, min_height=min_height,
                                       footprint=footprint, surface=(surface.in_bounds, surface.seen))
    doc = _document(rec, gt, state, window, report, score, measures, time.perf_counter() - t0)
    doc["warnings"] = (surface.warnings + coarse_spacing_warnings(surface.spacing, threshold, len(surface.observed))
                       + state_warnings(gt, state, window) + init_warnings(report, gt)
                       + seen_outside_warnings(surface, rec.volume is not None))
    return FusionEvaluation(doc, rec, score)


def seen_outside_warnings(surface: ObservedSurface, grid: bool) -> list[str]:
    """A warning when more than SEEN_OUTSIDE_WARN of the true surface the cameras saw lies outside the
    reconstruction's extent (grid: its volume grid, else its bounding box): completeness leaves it out, so a grid
    that crops the scene looks more complete than the whole view is."""
    share = surface.seen_outside_share
    if share is None or share <= SEEN_OUTSIDE_WARN:
        return []
    where = "the volume grid" if grid else "the reconstruction's bounding box (grown by the region margin)"
    inside = len(surface.observed)
    return [f"{100 * share:.0f} % of the true surface the cameras saw ({surface.seen_outside} of "
            f"{surface.seen_outside + inside} samples) lies outside {where}: completeness counts only the "
            f"{inside} inside, so it speaks for a part of the view and scores a cropped scene higher than a whole "
            f"one (reconstruction.visible_share_outside; fuse with a grid that holds the scene)"]


def init_warnings(report: dict | None, gt: GroundTruth | None = None) -> list[str]:
    """A volume that continued another (fuse's init) with no sphere forgotten (no POIs, no spheres cleared): the
    state check above sees only this run's window, but the init volume's frames, taken before it, are in the
    reconstruction too, so where the scene changed both states blend with no word. One warning (the init volume,
    how many of the volume's frames it brought, its window when its report.json says it)."""
    grid = (report or {}).get("grid") if isinstance(report, dict) else None
    if not isinstance(grid, dict) or not isinstance(grid.get("sizing"), dict) or grid["sizing"].get("mode") != "init":
        return []
    if report.get("cleared_spheres"):
        return []
    init = grid["sizing"].get("init")
    if not isinstance(init, str):  # a report written before sizing named the init volume: its placement line does
        placement = grid.get("placement") if isinstance(grid.get("placement"), str) else ""
        init = placement.split(" ", 1)[1] if " " in placement else "another volume"
    total, used = grid.get("frames_in_volume"), (report.get("frames") or {}).get("used")
    brought = ""
    if all(isinstance(v, int) and not isinstance(v, bool) for v in (total, used)) and total > used:
        brought = f" ({total - used} of its {total} frames)"
    earlier = fused_window(report_json_of(init)) if init != "another volume" else None
    when = "" if earlier is None else (f", fused from {_seconds(earlier[0], 'the start')} to "
                                       f"{_seconds(earlier[1], 'the end')}")
    moved = ""
    if gt is not None and gt.changes:
        moved = f" (here {', '.join(sorted({str(c.get('object', '?')) for c in gt.changes}))} moved)"
    return [f"the volume continues {init}{brought}{when}, and no POI or sphere was forgotten before fusing: the "
            f"states are checked only against this run's frames, but the earlier frames are in the reconstruction "
            f"too, so where the scene changed{moved} both states are blended; forget the POIs' spheres when "
            f"continuing a volume (fuse's clear_pois), or fuse one window alone"]


def _seconds(v, open_end: str) -> str:
    """A window end in seconds, or what an open end means."""
    return open_end if v is None else f"{v:g} s"


def state_warnings(gt: GroundTruth, state: str, window: tuple | None) -> list[str]:
    """What the fused frames (all, or those in the report's window) hold against the state scored: both sides of
    the change (the moved objects blended between their places), or only the other state's frames."""
    scan = gt.info.get("frames", {}).get("scan")
    if not gt.changes or scan is None:
        return []
    idx = state_frames(gt, "after", window)
    before, after = int(np.count_nonzero(idx < int(scan))), int(np.count_nonzero(idx >= int(scan)))
    moved = ", ".join(sorted({str(c.get("object", "?")) for c in gt.changes}))
    if before and after:
        return [f"the fused frames span the change ({before} scan and {after} after-change frames): the objects the "
                f"hand moved ({moved}) are blended between their places, so their measures are off; fuse a time "
                f"window before or after the change to score one state"]
    if (state == "after" and not after) or (state == "before" and not before):
        return [f"the fused frames are all {'scan' if before else 'after-change'} frames, scored against the "
                f"{state} state: the objects the hand moved ({moved}) are where the other state has them"]
    return []


def _document(rec: Reconstruction, gt: GroundTruth, state: str, window: tuple | None, report: dict | None,
              score: ReconstructionScore, measures: ObjectMeasuresResult, seconds: float) -> dict:
    """The results document, strict JSON (NaN / inf as null)."""
    mode = (report or {}).get("pose_mode")
    mode = mode if isinstance(mode, str) else None
    tracking = POSE_MODE_LABELS.get(mode, mode or "as fused")
    objs = measures.to_json()
    doc = {
        "input": {"reconstruction": str(rec.source), "volume": str(rec.volume_path) if rec.volume_path else None,
                  "vertices": int(len(rec.vertices)), "triangles": int(len(rec.triangles)),
                  "ground_truth": str(gt.folder), "state": state, "pose_mode": tracking,
                  "fused_window_s": list(window) if window else None, "error_mesh": None},
        "reconstruction": score.to_json(),
        "objects": objs,
        "table_1": PAPER_TABLE_1 + [{"scenario": "this run", "tracking": tracking, "mean_abs": objs["mean_abs"],
                                     "std": objs["std"], "objects_measured": objs["objects_measured"],
                                     "objects_total": objs["objects_total"]}],
        "seconds": seconds,
    }
    return _finite(doc)


def _finite(obj):
    """NaN / inf -> None throughout (strict JSON)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
