"""`kinfu segment` as a library call: volume -> surface cloud -> segments -> saliency -> superquadrics -> files.

`analyse_cloud(points, normals, options)` and `analyse_volume(volume, options)` return a
`SegmentResult`; `write_segment_outputs(result, outdir)` writes segments.ply, saliency.ply,
segments.json (and PNG renders with plot=True), each atomically.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import read_ternary
from kinfu_cli.fusion.volume import load_volume
from kinfu_cli.segmentation.saliency import SegmentSaliency, segment_saliency
from kinfu_cli.segmentation.segments import PLANE_LABEL, Segmentation, SegmentationParams, segment_cloud
from kinfu_cli.segmentation.superquadric import SegmentError, SuperquadricFit, fit_superquadric
from kinfu_cli.segmentation.surface import SurfaceCloud, surface_from_volume


@dataclass
class SegmentOptions:
    resolution: float = 0.01  # surface cloud thinning (m)
    min_weight: float = 1.0  # TSDF weight for a voxel to count as observed
    isolation_threshold: float = 0.02  # B_th (m), eq. 3.11
    superquadrics: bool = True
    sq_max_points: int = 200
    sq_exponent_bounds: tuple[float, float] = (0.1, 1.9)
    sq_cost: str = "volume"
    sq_min_points: int = 30
    multi_sq: bool = False  # thesis ch. 8 split for segments whose single fit is poor
    msq_trigger: float = 0.005  # single-superquadric RMS residual (m) above which the split is tried
    msq_height: int = 3
    msq_mu: float = 0.03
    segmentation: SegmentationParams = field(default_factory=SegmentationParams)


@dataclass
class SegmentResult:
    cloud: SurfaceCloud
    segmentation: Segmentation
    saliency: list[SegmentSaliency]  # decreasing saliency, support plane excluded
    superquadrics: dict[int, SuperquadricFit | str]  # fit, or the reason there is none
    timing: dict[str, float]
    options: SegmentOptions
    multi: dict = field(default_factory=dict)  # segment id -> MultiSuperquadric (with options.multi_sq)

    def most_salient(self) -> SegmentSaliency | None:
        return self.saliency[0] if self.saliency else None

    def to_json(self) -> dict:
        segs = []
        seg = self.segmentation
        entries = list(self.saliency)
        plane_pts = seg.points[seg.labels == PLANE_LABEL]
        for rank, s in enumerate(entries, start=1):
            sq = self.superquadrics.get(s.id)
            segs.append({
                "id": s.id, "kind": "object", "rank": rank, "point_count": s.n_points,
                "centroid": s.centroid.tolist(), "oriented_box": s.box.to_json(),
                "bounding_sphere": {"center": s.box.center.tolist(), "radius": s.bounding_radius},
                "isolation": s.isolation, "roundness": s.roundness, "saliency": s.saliency,
                "superquadric": sq.to_json() if isinstance(sq, SuperquadricFit) else None,
                **({"superquadric_error": sq} if isinstance(sq, str) else {}),
                **({"multi_superquadric": self.multi[s.id].to_json()} if s.id in self.multi else {}),
            })
        if len(plane_pts):
            from kinfu_cli.segmentation.saliency import oriented_box

            box = oriented_box(plane_pts)
            segs.append({"id": PLANE_LABEL, "kind": "support_plane", "rank": None, "point_count": int(len(plane_pts)),
                         "centroid": plane_pts.mean(axis=0).tolist(), "oriented_box": box.to_json(),
                         "plane": None if seg.plane is None else seg.plane.tolist(),
                         "isolation": None, "roundness": None, "saliency": None, "superquadric": None})
        opts = asdict(self.options)
        return {"segments": segs, "support_plane": None if seg.plane is None else seg.plane.tolist(),
                "points": int(len(seg.points)), "noise_points": int(np.sum(seg.labels < 0)),
                "stats": seg.stats, "timing_s": self.timing, "options": opts}


def analyse_cloud(points: np.ndarray, normals: np.ndarray, options: SegmentOptions | None = None,
                  timing: dict | None = None) -> SegmentResult:
    """Segment a surface cloud, score saliency, fit superquadrics."""
    options = options or SegmentOptions()
    timing = dict(timing or {})
    t = time.perf_counter()
    seg = segment_cloud(points, normals, options.segmentation)
    timing["segmentation"] = time.perf_counter() - t
    t = time.perf_counter()
    sal = segment_saliency(seg.points, seg.labels, b_th=options.isolation_threshold, exclude=(-1, PLANE_LABEL))
    timing["saliency"] = time.perf_counter() - t
    t = time.perf_counter()
    fits: dict[int, SuperquadricFit | str] = {}
    if options.superquadrics:
        for s in sal:
            if s.n_points < options.sq_min_points:
                fits[s.id] = f"{s.n_points} points (< --sq-min-points {options.sq_min_points})"
                continue
            try:
                fits[s.id] = fit_superquadric(seg.points[seg.labels == s.id], max_points=options.sq_max_points,
                                              exponent_bounds=options.sq_exponent_bounds, cost=options.sq_cost)
            except SegmentError as exc:
                fits[s.id] = str(exc)
    timing["superquadrics"] = time.perf_counter() - t
    multi = {}
    if options.superquadrics and options.multi_sq:
        from kinfu_cli.segmentation.multi_superquadric import fit_multi_superquadric

        t = time.perf_counter()
        for sid, fit in fits.items():
            if isinstance(fit, SuperquadricFit) and fit.residual > options.msq_trigger:
                try:
                    multi[sid] = fit_multi_superquadric(
                        seg.points[seg.labels == sid], height=options.msq_height, mu=options.msq_mu,
                        min_points=options.sq_min_points, max_points=options.sq_max_points,
                        exponent_bounds=options.sq_exponent_bounds, cost=options.sq_cost)
                except SegmentError:
                    pass
        timing["multi_superquadrics"] = time.perf_counter() - t
    return SegmentResult(SurfaceCloud(seg.points, seg.normals), seg, sal, fits, timing, options, multi)


def analyse_volume(volume, options: SegmentOptions | None = None) -> SegmentResult:
    """From a fusion TernaryVolume or a TernaryGrid."""
    options = options or SegmentOptions()
    t = time.perf_counter()
    cloud = surface_from_volume(volume, min_weight=options.min_weight, resolution=options.resolution)
    t_surface = time.perf_counter() - t
    if len(cloud) < options.segmentation.min_segment_points:
        raise VolumeError(f"volume surface has only {len(cloud)} points: nothing to segment")
    return analyse_cloud(cloud.points, cloud.normals, options, {"surface": t_surface})


def load_segment_input(path: str | os.PathLike):
    """A fusion volume.npz (TSDF + weights) or a ternary.npz (labels only)."""
    path = Path(path)
    if not path.exists():
        raise VolumeError(f"{path}: no such volume file")
    grid = read_ternary(path)
    return grid if grid is not None else load_volume(path)


def segment_colors(labels: np.ndarray) -> np.ndarray:
    """A distinct colour per segment (support plane grey, dropped points black)."""
    rng = np.random.default_rng(7)
    n = int(max(labels.max(), 0)) + 1
    pal = rng.uniform(0.15, 1.0, size=(n, 3))
    col = pal[np.maximum(labels, 0)]
    col[labels == PLANE_LABEL] = 0.6
    col[labels < 0] = 0.0
    return col


def saliency_colors(points_labels: np.ndarray, saliency: list[SegmentSaliency]) -> np.ndarray:
    """Per-point colour from the segment saliency (viridis; support plane and noise dark grey)."""
    from matplotlib import colormaps

    val = np.full(len(points_labels), np.nan)
    for s in saliency:
        val[points_labels == s.id] = s.saliency
    col = np.asarray(colormaps["viridis"](np.nan_to_num(val, nan=0.0)))[:, :3]
    col[np.isnan(val)] = 0.25
    return col


def write_segment_outputs(result: SegmentResult, outdir: str | os.PathLike, plot: bool = False) -> dict[str, Path]:
    """segments.ply, saliency.ply, segments.json (+ segments.png, saliency.png with plot)."""
    import open3d as o3d

    from kinfu_cli.core.atomic import atomic_path, write_json

    out = Path(outdir)
    seg = result.segmentation
    files: dict[str, Path] = {}
    for name, col in (("segments.ply", segment_colors(seg.labels)),
                      ("saliency.ply", saliency_colors(seg.labels, result.saliency))):
        pc = SurfaceCloud(seg.points, seg.normals).to_open3d(col)
        with atomic_path(out / name) as tmp:
            if not o3d.io.write_point_cloud(str(tmp), pc, write_ascii=False):
                raise VolumeError(f"{out / name}: open3d could not write the point cloud")
        files[name] = out / name
    if plot:
        from kinfu_cli.report.segment_plot import plot_segments

        files.update(plot_segments(result, out))
    files["segments.json"] = write_json(out / "segments.json", result.to_json())
    return files
