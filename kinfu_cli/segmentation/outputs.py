"""The files of `kinfu segment`: segments.ply and saliency.ply (the surface cloud coloured by segment and
by saliency; segments.ply also holds the integer per-point `label`, a labels file) and segments.json, each
written atomically. The colours are shared with the PNG renders."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from kinfu_cli.core.atomic import atomic_path, write_json
from kinfu_cli.segmentation.pipeline import SegmentResult
from kinfu_cli.segmentation.saliency import SegmentSaliency
from kinfu_cli.segmentation.segments import PLANE_LABEL

# every entry `kinfu segment` may write in its output folder (with --grasp and --plot): the rest of a shared folder
# (another command's outputs) is left alone when it writes there again
SEGMENT_ENTRIES = ("segments.json", "segments.ply", "saliency.ply", "grasps.json", "segments.png", "saliency.png",
                   "colors.png")


def segment_colors(labels: np.ndarray) -> np.ndarray:
    """A distinct colour per segment (support plane grey, dropped points black)."""
    rng = np.random.default_rng(7)
    n = int(max(labels.max(), 0)) + 1
    pal = rng.uniform(0.15, 1.0, size=(n, 3))
    col = pal[np.maximum(labels, 0)]
    col[labels == PLANE_LABEL] = 0.6
    col[labels < 0] = 0.0
    return col


def viridis(values: np.ndarray) -> np.ndarray:
    """matplotlib's viridis (N x 3 RGB in 0..1) without importing matplotlib (0.135 s of every `kinfu segment`):
    its 256 colours, saved once as `matplotlib.colormaps["viridis"](np.linspace(0, 1, 256))[:, :3]` in
    viridis.npz, looked up as matplotlib does (entry floor(256 v), clipped to 0..255)."""
    with np.load(Path(__file__).with_name("viridis.npz")) as f:
        table = f["rgb"]
    idx = np.clip(np.floor(np.asarray(values, dtype=float) * len(table)), 0, len(table) - 1).astype(np.intp)
    return table[idx]


def saliency_colors(points_labels: np.ndarray, saliency: list[SegmentSaliency]) -> np.ndarray:
    """Per-point colour from the segment saliency (viridis; support plane and noise dark grey)."""
    val = np.full(len(points_labels), np.nan)
    for s in saliency:
        val[points_labels == s.id] = s.saliency
    col = viridis(np.nan_to_num(val, nan=0.0))
    col[np.isnan(val)] = 0.25
    return col


def _write_cloud(path: Path, seg, colors: np.ndarray, labels: np.ndarray | None) -> None:
    """Binary PLY of the segmentation's points: x, y, z, nx, ny, nz (float), red, green, blue (uchar) and an int
    `label` when given (the layout open3d's writer gave these files). Written by plyfile, which reads labels
    files too: open3d's import alone took 0.4 s of the 2 s `kinfu segment` budget."""
    from plyfile import PlyData, PlyElement  # only the PLY files need it

    fields = [(n, "<f4") for n in ("x", "y", "z", "nx", "ny", "nz")] + [(n, "u1") for n in ("red", "green", "blue")]
    vertex = np.empty(len(seg.points), dtype=fields + ([("label", "<i4")] if labels is not None else []))
    for names, values in ((("x", "y", "z"), seg.points), (("nx", "ny", "nz"), seg.normals),
                          (("red", "green", "blue"), np.round(np.clip(colors, 0, 1) * 255))):
        for j, name in enumerate(names):
            vertex[name] = values[:, j]
    if labels is not None:
        vertex["label"] = labels
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<",
                comments=["Created by kinfu segment"]).write(fh)


def write_segment_outputs(result: SegmentResult, outdir: str | os.PathLike, doc: dict | None = None
                          ) -> dict[str, Path]:
    """segments.ply, saliency.ply and segments.json in `outdir`; returns name -> path. segments.ply also carries
    the segment as an integer `label` (0 support plane, 1.. segments, -1 dropped), so readers need not decode
    colours. doc: `result.to_json()` when the caller has made it already."""
    out = Path(outdir)
    seg = result.segmentation
    _write_cloud(out / "segments.ply", seg, segment_colors(seg.labels), np.asarray(seg.labels, dtype=np.int32))
    _write_cloud(out / "saliency.ply", seg, saliency_colors(seg.labels, result.saliency), None)
    files = {"segments.ply": out / "segments.ply", "saliency.ply": out / "saliency.ply"}
    files["segments.json"] = write_json(out / "segments.json", result.to_json() if doc is None else doc)
    return files
