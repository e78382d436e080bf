"""The files of `kinfu segment`: segments.ply and saliency.ply (the surface cloud coloured by segment and
by saliency; segments.ply also holds the integer per-point `label`, a labels file) and segments.json, each
written atomically. The colours are shared with the PNG renders."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import atomic_path, write_json
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.segmentation.pipeline import SegmentResult
from kinfu_cli.segmentation.saliency import SegmentSaliency
from kinfu_cli.segmentation.segments import PLANE_LABEL
from kinfu_cli.segmentation.surface import SurfaceCloud


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
    from matplotlib import colormaps  # heavy; only the colour map is needed

    val = np.full(len(points_labels), np.nan)
    for s in saliency:
        val[points_labels == s.id] = s.saliency
    col = np.asarray(colormaps["viridis"](np.nan_to_num(val, nan=0.0)))[:, :3]
    col[np.isnan(val)] = 0.25
    return col


def write_segment_outputs(result: SegmentResult, outdir: str | os.PathLike) -> dict[str, Path]:
    """segments.ply, saliency.ply and segments.json in `outdir`; returns name -> path."""
    import open3d as o3d  # heavy; only the PLY writer is needed

    out = Path(outdir)
    seg = result.segmentation
    files: dict[str, Path] = {}
    for name, col in (("segments.ply", segment_colors(seg.labels)),
                      ("saliency.ply", saliency_colors(seg.labels, result.saliency))):
        pc = o3d.t.geometry.PointCloud.from_legacy(SurfaceCloud(seg.points, seg.normals).to_open3d())
        # colours as uint8 (what PLY viewers expect); segments.ply also carries the segment as an integer
        # `label` (0 support plane, 1.. segments, -1 dropped) so readers need not decode colours
        pc.point["colors"] = o3d.core.Tensor(np.round(np.clip(col, 0, 1) * 255).astype(np.uint8))
        if name == "segments.ply":
            pc.point["label"] = o3d.core.Tensor(np.asarray(seg.labels, dtype=np.int32).reshape(-1, 1))
        with atomic_path(out / name) as tmp:
            if not o3d.t.io.write_point_cloud(str(tmp), pc, write_ascii=False):
                raise VolumeError(f"{out / name}: open3d could not write the point cloud")
        files[name] = out / name
    files["segments.json"] = write_json(out / "segments.json", result.to_json())
    return files
