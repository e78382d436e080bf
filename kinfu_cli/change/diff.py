"""The `diff_volumes` driver: removed / added change regions between two fused volumes of one place.

Inputs are ternary grids (`ternary.npz`) or fusion volumes (`volume.npz`), in the same world frame with one
voxel size. The result lists every change region with its kind, centroid, axis-aligned box, volume and voxel
centres; `to_json()` is changes.json (its keys are documented in README.md, section `kinfu diff`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kinfu_cli.change.align import AlignedPair, align
from kinfu_cli.change.noise import (MODEL, NOISE_SIGMAS, nearest_distance, noise_margins, read_cameras,
                                   sensor_evidence)
from kinfu_cli.change.regions import KINDS, ChangeMasks, Region, find_changes
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.core.grid import TernaryGrid, read_ternary
from kinfu_cli.core.volume_file import read_volume_meta, report_json_of
from kinfu_cli.fusion.volume import load_volume

#: Smallest region kept, in voxels, when no minimum volume is given: a 3 x 3 x 3 block. Pose noise is already
#: removed by the free-space erosion; what it leaves are sensor speckles and mixed pixels at depth edges, a few
#: voxels each, while the smallest object a tabletop task moves (a few centimetres) leaves tens of voxels.
DEFAULT_MIN_VOXELS = 27
#: Below this overlap (voxels known in both over the known voxels of the smaller volume) the diff warns.
MIN_OVERLAP = 0.5
#: Above this share of a volume's observed voxels outside the common box (the other grid is smaller or shifted)
#: the diff warns: nothing there is compared. Two auto-sized fusions of one place from different views leave up
#: to ~15 % out (sample pick-and-place pair: 14 % of the scan's observed voxels lie outside the later fusion's
#: grid); a quarter is well past that, and a moved object in it would be missed without a word.
MAX_OUTSIDE_BOX = 0.25


@dataclass
class ChangeParams:
    """margin: free-space erosion in voxels (pose noise tolerated); min_volume: smallest region kept, m^3 (None:
    DEFAULT_MIN_VOXELS voxels); noise_sigmas: the margin also grows to this many standard deviations of the
    depth noise at each voxel's distance from the cameras (change/noise.py; 0: off, and off when no camera
    positions are known)."""

    margin: int = 1
    min_volume: float | None = None
    noise_sigmas: float = NOISE_SIGMAS

    def min_voxels(self, voxel_size: float) -> int:
        if self.min_volume is None:
            return DEFAULT_MIN_VOXELS
        return max(1, int(np.ceil(self.min_volume / voxel_size ** 3 - 1e-9)))

    def check(self) -> None:
        check_number(self.margin, "margin", 0, 10, integer=True)
        if self.min_volume is not None:
            check_number(self.min_volume, "min_volume", 0, 1e3, unit="m^3")
        check_number(self.noise_sigmas, "noise_sigmas", 0, 10)


@dataclass
class ChangeRegion:
    """A change region in world coordinates: points (N, 3) are its voxel centres."""

    id: int
    kind: str
    points: np.ndarray
    voxel_size: float

    @property
    def centroid(self) -> np.ndarray:
        return self.points.mean(axis=0)

    @property
    def volume(self) -> float:
        return len(self.points) * self.voxel_size ** 3

    def to_json(self) -> dict:
        half = self.voxel_size / 2
        return {"id": self.id, "kind": self.kind, "centroid": [round(float(v), 5) for v in self.centroid],
                "box_min": [round(float(v), 5) for v in self.points.min(axis=0) - half],
                "box_max": [round(float(v), 5) for v in self.points.max(axis=0) + half],
                "volume_m3": float(self.volume), "voxels": int(len(self.points)), "ply": f"regions/{self.id}.ply"}


@dataclass
class ChangeResult:
    """What `kinfu diff` reports: the regions, the cleaning counts, the common box and the warnings."""

    before: str
    after: str
    frame: str
    pair: AlignedPair
    masks: ChangeMasks
    regions: list[ChangeRegion]
    params: ChangeParams
    min_voxels: int
    warnings: list[str] = field(default_factory=list)
    pois: dict | None = None  # filled by evaluation.change_pois.score_pois_in_comparison
    cameras: dict[str, int] | None = None  # camera positions used for the depth-noise margin, per volume
    sensors: dict[str, dict] | None = None  # per volume, whether its camera looks like the noise model's (noise.py)
    grid_boxes: dict[str, tuple[np.ndarray, np.ndarray]] | None = None  # per volume, its whole grid's min / max corner

    def count(self, kind: str) -> int:
        return sum(1 for r in self.regions if r.kind == kind)

    def to_json(self) -> dict:
        p, m = self.pair, self.masks
        return {
            "before": self.before, "after": self.after, "frame": self.frame, "voxel_size": p.voxel_size,
            "common_box": {"min": [float(v) for v in p.origin],
                           "max": [float(v) for v in p.origin + np.array(p.shape) * p.voxel_size],
                           "shape": list(p.shape)},
            "overlap": {"fraction": round(p.overlap, 4), "observed_before": p.observed_before,
                        "observed_after": p.observed_after, "observed_both": p.observed_both,
                        **{k: {"in_common_box": getattr(p, f"in_box_{k}"),
                               "in_common_box_fraction": round(p.in_box_fraction(k), 4),
                               "compared_fraction": round(p.compared_fraction(k), 4)} for k in ("before", "after")}},
            "parameters": {"margin_voxels": self.params.margin, "min_volume_m3": self.min_voxels * p.voxel_size ** 3,
                           "min_voxels": self.min_voxels, "connectivity": 26,
                           "depth_noise": None if self.cameras is None else {
                               "model": MODEL, "sigmas": self.params.noise_sigmas, "cameras": self.cameras,
                               "sensors": self.sensors}},
            "counts": {"changed_voxels": m.raw, "after_erosion": m.kept, "unknown_ignored": m.unknown_ignored,
                       "unknown_hidden_blobs": m.hidden,
                       "within_depth_noise": m.within_noise,
                       "within_depth_noise_regions": None if m.within_noise is None else {
                           k: sum(r.kind == k for r in m.within_noise_regions) for k in KINDS},
                       "dropped_small_regions": m.dropped_regions, "dropped_small_voxels": m.dropped_voxels,
                       "regions": {k: self.count(k) for k in KINDS},
                       "region_voxels": {k: sum(len(r.points) for r in self.regions if r.kind == k) for k in KINDS}},
            "regions": [r.to_json() for r in self.regions],
            "changes_ply": "changes.ply" if self.regions else None,
            "pois": self.pois,
            "warnings": list(self.warnings),
        }


# ups further apart than this are two world frames (estimated ups of one frame differ by a few degrees)
UP_DISAGREE_DEG = 20.0


def _warnings(before: TernaryGrid, after: TernaryGrid, names: tuple[str, str], pair: AlignedPair,
              masks: ChangeMasks, n_regions: int, min_voxels: int) -> list[str]:
    out = []
    fb, fa = before.frame.lstrip("/"), after.frame.lstrip("/")
    if fb and fa and fb != fa:
        out.append(f"{names[0]} is in frame {fb!r}, {names[1]} in {fa!r}; compared at their coordinates as given")
    if before.up is not None and after.up is not None:
        angle = float(np.degrees(np.arccos(np.clip(before.up @ after.up, -1.0, 1.0))))
        if angle > UP_DISAGREE_DEG:
            out.append(f"the volumes' up directions differ by {angle:.0f} deg ({np.round(before.up, 3).tolist()} "
                       f"vs {np.round(after.up, 3).tolist()}): their world frames are not one (a z-up and a y-down "
                       f"frame, or another tilt), so the regions mostly show that difference")
    if pair.observed_both == 0:
        out.append(f"no voxel is observed in both {names[0]} and {names[1]}: nothing can be compared")
    elif pair.overlap < MIN_OVERLAP:
        out.append(f"the volumes overlap little: {100 * pair.overlap:.0f} % of the smaller one's observed voxels "
                   f"are observed in both (below {100 * MIN_OVERLAP:.0f} %); changes elsewhere cannot be seen")
    for key, name, other, other_name in (("before", names[0], after, names[1]), ("after", names[1], before, names[0])):
        observed = getattr(pair, f"observed_{key}")
        outside = observed - getattr(pair, f"in_box_{key}")
        if observed and outside > MAX_OUTSIDE_BOX * observed:
            lo, hi = other.origin, other.origin + np.array(other.shape) * other.voxel_size
            out.append(f"{name}: {outside} of its {observed} observed voxels ({100 * outside / observed:.0f} %, more "
                       f"than {100 * MAX_OUTSIDE_BOX:.0f} %) lie outside {other_name}'s grid "
                       f"{np.round(lo, 3).tolist()}..{np.round(hi, 3).tolist()} m and were not compared (only "
                       f"{100 * pair.compared_fraction(key):.0f} % of its observed voxels are observed in both); "
                       f"changes there cannot be seen (fuse both over one grid: the same origin and size)")
    if n_regions == 0 and sum(masks.hidden.values()):
        u = masks.hidden
        out.append(f"no change found, but {u['occupied_before_unknown_after']} voxels occupied before lie in space "
                   f"unknown after and {u['occupied_after_unknown_before']} occupied after in space unknown before, "
                   f"in blobs as large as a region: changes there cannot be seen")
    return out


def diff_grids(before: TernaryGrid, after: TernaryGrid, params: ChangeParams | None = None,
               names: tuple[str, str] = ("before", "after"),
               cameras: tuple[np.ndarray | None, np.ndarray | None] = (None, None),
               reports: tuple[dict | None, dict | None] = (None, None)) -> ChangeResult:
    """The change regions from `before` to `after` (grids of one place, one voxel size); cameras: the camera
    positions (M, 3) each was fused from, for the depth-noise margin (one stands for both; none: fixed margin);
    reports: the report.json of the `kinfu fuse` runs that wrote them (what sensor they saw), when known."""
    params = params or ChangeParams()
    params.check()
    pair = align(before, after, *names)
    min_voxels = params.min_voxels(pair.voxel_size)
    cam_b = cameras[0] if cameras[0] is not None else cameras[1]
    cam_a = cameras[1] if cameras[1] is not None else cameras[0]
    margin_of = None
    if cam_b is not None and params.noise_sigmas > 0:
        def margin_of(idx):
            return noise_margins(pair.centers(idx), cam_b, cam_a, params.noise_sigmas, pair.voxel_size)
    masks = find_changes(pair.before, pair.after, margin=params.margin, min_voxels=min_voxels, margin_of=margin_of)
    regions = [ChangeRegion(i, r.kind, pair.centers(r.voxels), pair.voxel_size) for i, r in enumerate(masks.regions)]
    warnings = _warnings(before, after, names, pair, masks, len(regions), min_voxels)
    used = sensors = None
    if margin_of is not None:
        used = {"before": 0 if cameras[0] is None else len(cameras[0]),
                "after": 0 if cameras[1] is None else len(cameras[1])}
        sensors = {k: sensor_evidence(g.intrinsics, rep) for k, g, rep in zip(("before", "after"), (before, after),
                                                                               reports)}
        warnings += _noise_warnings(pair, masks, (cam_b, cam_a), names, sensors)
    boxes = {k: (g.origin.copy(), g.origin + np.array(g.shape) * g.voxel_size)
             for k, g in (("before", before), ("after", after))}
    return ChangeResult(names[0], names[1], before.frame or after.frame, pair, masks, regions, params, min_voxels,
                        warnings, cameras=used, sensors=sensors, grid_boxes=boxes)


def _noise_warnings(pair: AlignedPair, masks: ChangeMasks, cameras: tuple[np.ndarray, np.ndarray],
                    names: tuple[str, str], sensors: dict[str, dict]) -> list[str]:
    """What the depth-noise margin may hide: clusters as large as a region it dropped (how many, of which kind,
    how far from the nearest camera), and a volume whose camera is evidently not the noise model's sensor."""
    out = []
    if masks.within_noise_regions:
        far = [float(np.median(np.minimum(nearest_distance(pair.centers(r.voxels), cameras[0]),
                                          nearest_distance(pair.centers(r.voxels), cameras[1]))))
               for r in masks.within_noise_regions]
        kinds = ", ".join(f"{sum(r.kind == k for r in masks.within_noise_regions)} {k}" for k in KINDS
                          if any(r.kind == k for r in masks.within_noise_regions))
        voxels = sorted(len(r.voxels) for r in masks.within_noise_regions)
        span = f"{min(far):.1f} m" if max(far) - min(far) < 0.05 else f"{min(far):.1f}-{max(far):.1f} m"
        out.append(f"{len(far)} cluster(s) of changed voxels as large as a region ({kinds}; {voxels[0]}"
                   f"{'' if len(voxels) == 1 else f'-{voxels[-1]}'} voxels), {span} from the cameras, were dropped "
                   f"as depth noise: a real change may hide there (a smaller noise_sigmas keeps them as regions)")
    for key, name in zip(("before", "after"), names):
        if sensors[key]["kinect_like"] is False:
            out.append(f"{name}: {sensors[key]['evidence']}: the depth-noise margin uses the Kinect v1 model, not "
                       f"this sensor's, so how much it drops far from the cameras is only indicative")
    return out


def diff_volumes(before: str | os.PathLike, after: str | os.PathLike,
                 params: ChangeParams | None = None) -> ChangeResult:
    """`diff_grids` on two files (ternary.npz or volume.npz); VolumeError naming the file for a missing or
    foreign file."""
    (params or ChangeParams()).check()  # bad parameters fail before any file is read
    cams = [read_cameras(p) for p in (before, after)]
    grids = _load(before), _load(after)
    names = str(Path(before)), str(Path(after))
    result = diff_grids(*grids, params, names, (cams[0][0], cams[1][0]),
                        tuple(report_json_of(p) for p in (before, after)))
    result.warnings[:0] = _same_volume_warnings(before, after, *grids, len(result.regions))
    result.warnings += [f"{why}; the depth-noise margin uses the other volume's cameras or none" for _, why in cams
                        if why]
    return result


def _same_volume_warnings(before: str | os.PathLike, after: str | os.PathLike, grid_before: TernaryGrid,
                          grid_after: TernaryGrid, n_regions: int) -> list[str]:
    """A volume diffed with itself (one file under two names: the same path, a symlink, a hard link; or two files
    holding identical grids) finds nothing by construction: its 0 changes say nothing about the scene."""
    try:
        same_file = os.path.samefile(before, after)
    except OSError:
        same_file = False
    if same_file:
        return [f"before and after are the same file ({Path(before)}): no change can be found, so {n_regions} "
                f"changes is not a finding"]
    if (grid_before.shape == grid_after.shape and grid_before.voxel_size == grid_after.voxel_size
            and np.array_equal(grid_before.origin, grid_after.origin)
            and np.array_equal(grid_before.labels, grid_after.labels)):
        return [f"{Path(before)} and {Path(after)} hold identical volumes (same grid, every voxel the same): no change "
                f"can be found, so {n_regions} changes is not a finding"]
    return []


def _load(path: str | os.PathLike) -> TernaryGrid:
    """The grid of a volume.npz or ternary.npz; VolumeError naming the file for anything else."""
    if read_volume_meta(path) is not None:
        return load_volume(path).ternary_grid()
    grid = read_ternary(path)
    if grid is None:
        raise VolumeError(f"{path}: neither a volume.npz nor a ternary.npz (expected the output of kinfu fuse)")
    return grid


__all__ = ["ChangeParams", "ChangeRegion", "ChangeResult", "Region", "diff_grids", "diff_volumes"]
