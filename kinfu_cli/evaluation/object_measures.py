"""The paper's object measures (Monica et al. RAS 2016 Table 1 / thesis Table 2.1): per object the height above
the table plane and the major / minor axis of its footprint on the table, reconstructed vs ground truth.

Reconstruction side (points = reconstructed mesh vertices):
1. table plane: RANSAC plane (open3d `segment_plane`, then a least-squares refit on its inliers) through the points
   near the true table top (within `band` of it, inside the table outline, outside every object's box), normal up
   (the true plane, said so in the results, when fewer than 50 such points exist);
2. an object's points: inside its true oriented box (changes.json centre / size / yaw) grown by `margin`
   horizontally and by `margin` + 5 cm up and down, and more than `min_height` above the fitted plane (so table
   points are left out);
3. height = the largest distance of its points above the plane; footprint = the points projected onto the plane,
   major / minor axis = the sides of their minimum-area rectangle (OpenCV `minAreaRect`), or with
   footprint="pca" the extents along the principal axes.
Ground-truth side: the same height / footprint measures of the object's true mesh vertices (objects/<id>.ply,
moved back to `center_before` for the before state) above the true table plane (`table.top_z`).

Errors: per object and measure (reconstructed - true); Table 1 pools the three measures over all objects: the
mean absolute error and the standard deviation of the errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import open3d as o3d

from kinfu_cli.core.errors import ConfigError, RecordingError
from kinfu_cli.core.poses import plane_axes
from kinfu_cli.io.messages import c_stderr_silenced

# Monica et al. RAS 2016 Table 1 (thesis Table 2.1): mean abs. / st. dev. (m) of the object measure errors
PAPER_TABLE_1 = [
    {"scenario": 1, "tracking": "egomotion", "mean_abs": 0.031, "std": 0.040},
    {"scenario": 1, "tracking": "robot kinematics", "mean_abs": 0.005, "std": 0.006},
    {"scenario": 2, "tracking": "egomotion", "mean_abs": 0.027, "std": 0.041},
    {"scenario": 2, "tracking": "robot kinematics", "mean_abs": 0.006, "std": 0.008},
]
MEASURES = ("height", "major", "minor")
VERTICAL_SLACK = 0.05  # m: extra room above / below an object's box (a height error must not be cut off)
FOOTPRINTS = ("rect", "pca")


@dataclass
class GroundTruthObject:
    """One object of the true scene in a state: id, shape, oriented box (centre, size, yaw) and mesh vertices."""

    id: str
    shape: str
    center: np.ndarray
    size: np.ndarray
    yaw: float
    vertices: np.ndarray

    def in_box(self, points: np.ndarray, margin: float = 0.0, margin_z: float | None = None) -> np.ndarray:
        """Points inside the oriented box grown by `margin` (horizontally; by `margin_z` up and down, default
        `margin`)."""
        p = np.asarray(points, dtype=np.float64) - self.center
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        lx = c * p[:, 0] + s * p[:, 1]
        ly = -s * p[:, 0] + c * p[:, 1]
        hx, hy, hz = 0.5 * self.size
        mz = margin if margin_z is None else margin_z
        return (np.abs(lx) <= hx + margin) & (np.abs(ly) <= hy + margin) & (np.abs(p[:, 2]) <= hz + mz)


def ground_truth_objects(gt, state: str = "after") -> list[GroundTruthObject]:
    """The objects present in `state` with their true vertices (after-state meshes, shifted to `center_before`
    for the before state; an object without a mesh file is cut out of the scene mesh by its box)."""
    if state not in ("after", "before"):
        raise ConfigError(f"expected after or before, got {state!r}", parameter="state")
    meshes = None
    out = []
    for o in gt.objects:
        try:
            present = bool(o["present_after"] if state == "after" else o["present_before"])
            center = np.asarray(o.get("center_before", o["center"]) if state == "before" else o["center"], float)
            size = np.asarray(o["size"], dtype=float)
            yaw = float(o.get("yaw", 0.0))
            oid = str(o["id"])
        except (KeyError, TypeError, ValueError) as exc:
            raise RecordingError(f"{gt.folder}/changes.json: object entry without id/center/size ({exc})") from None
        if not present:
            continue
        if center.shape != (3,) or size.shape != (3,) or not np.all(size > 0):
            raise RecordingError(f"{gt.folder}/changes.json: object {oid}: center and size must be 3 numbers (size > 0)")
        path = gt.folder / "objects" / f"{oid}.ply"
        obj = GroundTruthObject(oid, str(o.get("shape", "")), center, size, yaw, np.zeros((0, 3)))
        if path.exists() and bool(o.get("present_after", True)):
            # no reader chatter (open3d warnings, RPly's own lines on a damaged PLY): we report problems
            with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error), c_stderr_silenced():
                v = np.asarray(o3d.io.read_triangle_mesh(str(path)).vertices, dtype=np.float64)
            obj.vertices = v + (center - np.asarray(o["center"], dtype=float))
        else:
            if meshes is None:
                meshes = np.asarray(gt.mesh(state).vertices, dtype=np.float64)
            obj.vertices = meshes[obj.in_box(meshes, 1e-4)]
        if len(obj.vertices) == 0:
            raise RecordingError(f"{gt.folder}: no ground-truth geometry for object {oid} in the {state} state")
        out.append(obj)
    return out


def table_plane_truth(gt) -> np.ndarray:
    """True table plane (a, b, c, d) with a x + b y + c z + d = 0, unit normal up."""
    t = gt.info.get("table")
    if not t:
        raise RecordingError(f"{gt.folder}/changes.json: no 'table' entry (needed for the object measures)")
    if "plane" in t:
        pl = np.asarray(t["plane"], dtype=float)
    else:
        pl = np.array([0.0, 0.0, 1.0, -float(t["top_z"])])
    pl = pl / np.linalg.norm(pl[:3])
    return pl if pl[2] >= 0 else -pl


def fit_table_plane(points: np.ndarray, gt, objects: list[GroundTruthObject], band: float = 0.05,
                    distance: float = 0.005, seed: int = 0) -> np.ndarray:
    """RANSAC plane through the reconstructed points near the true table top (see module docstring)."""
    truth = table_plane_truth(gt)
    t = gt.info["table"]
    p = np.asarray(points, dtype=np.float64)
    near = np.abs(p @ truth[:3] + truth[3]) <= band
    half = 0.5 * np.asarray(t.get("size", [np.inf, np.inf]), dtype=float)
    cxy = np.asarray(t.get("center", [0.0, 0.0]), dtype=float)
    near &= np.all(np.abs(p[:, :2] - cxy) <= half, axis=1)
    for o in objects:
        near &= ~o.in_box(p, 0.03)
    cand = p[near]
    if len(cand) < 50:
        raise RecordingError(f"too few reconstructed points ({len(cand)}) near the true table top to fit the table "
                             f"plane (is the reconstruction in the ground truth's world frame?)")
    o3d.utility.random.seed(seed)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cand))
    # one thread: open3d's parallel RANSAC stops early, so on several threads the seeded plane depended on
    # thread timing and the results changed from run to run
    threads = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        _, inliers = pc.segment_plane(distance_threshold=distance, ransac_n=3, num_iterations=500)
    finally:
        o3d.utility.set_max_threads(threads)
    q = cand[np.asarray(inliers, dtype=np.int64)]
    # least-squares refit on the RANSAC inliers (centroid + direction of least spread)
    c = q.mean(axis=0)
    n = np.linalg.svd(q - c, full_matrices=False)[2][-1]
    n = n if n @ truth[:3] >= 0 else -n
    return np.array([n[0], n[1], n[2], -float(n @ c)])


def footprint_axes(xy: np.ndarray, method: str = "rect") -> tuple[float, float]:
    """(major, minor) length of a 2-D point set: sides of its minimum-area rectangle ("rect", OpenCV) or its
    extents along its principal axes ("pca")."""
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) < 3:
        return float("nan"), float("nan")
    if method == "rect":
        c = xy.mean(axis=0)
        (_, _), (w, h), _ = cv2.minAreaRect(((xy - c) * 1000.0).astype(np.float32))  # mm: float32-friendly
        w, h = w / 1000.0, h / 1000.0
    elif method == "pca":
        q = xy - xy.mean(axis=0)
        _, vecs = np.linalg.eigh(q.T @ q)
        ext = q @ vecs
        w, h = np.ptp(ext[:, 0]), np.ptp(ext[:, 1])
    else:
        raise ConfigError(f"expected one of {', '.join(FOOTPRINTS)}, got {method!r}", parameter="method")
    return float(max(w, h)), float(min(w, h))


def measure(points: np.ndarray, plane: np.ndarray, method: str = "rect") -> dict:
    """Height above the plane and footprint axes of an object's points."""
    n, d = plane[:3], plane[3]
    h = points @ n + d
    e1, e2 = plane_axes(n)
    major, minor = footprint_axes(np.stack([points @ e1, points @ e2], axis=1), method)
    return {"height": float(h.max()) if len(h) else float("nan"), "major": major, "minor": minor}


@dataclass
class ObjectMeasuresResult:
    objects: list  # per object: id, shape, points, true {...}, measured {...}, error {...}
    plane: np.ndarray
    plane_truth: np.ndarray
    mean_abs: float
    std: float | None
    per_measure: dict
    settings: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        tilt = float(np.degrees(np.arccos(np.clip(abs(self.plane[:3] @ self.plane_truth[:3]), 0, 1))))
        measured = sum(1 for o in self.objects if o["error"] is not None)
        return {"objects": self.objects, "objects_measured": measured, "objects_total": len(self.objects),
                "mean_abs": self.mean_abs, "std": self.std, "per_measure": self.per_measure,
                "table_plane": {"source": self.settings.get("table_plane", "fitted"),
                                "fitted": self.plane.tolist(), "true": self.plane_truth.tolist(),
                                "tilt_deg": tilt, "offset": float(self.plane[3] - self.plane_truth[3])},
                "paper_table_1": PAPER_TABLE_1, "settings": self.settings}


def _seen_share(o: GroundTruthObject, plane: np.ndarray, samples: np.ndarray, seen: np.ndarray) -> float | None:
    """Share of the true-surface samples on this object (in its box, >= 2 mm above the table) that were seen."""
    s = np.asarray(samples, dtype=np.float64)
    on = o.in_box(s, 0.002) & (s @ plane[:3] + plane[3] >= 0.002)
    return float(np.mean(np.asarray(seen)[on])) if on.any() else None


def _std(v) -> float | None:
    """Sample standard deviation of the signed errors (the paper's st. dev. exceeds its mean abs. error, so it is
    not the spread of the absolute values); 0 for one value, None for none."""
    v = np.asarray(v, dtype=float)
    if v.size == 0:
        return None
    return float(np.std(v, ddof=1)) if v.size > 1 else 0.0


def object_measures(points: np.ndarray, gt, state: str = "after", margin: float = 0.02, min_height: float = 0.005,
                    footprint: str = "rect", min_points: int = 20, surface: tuple | None = None
                    ) -> ObjectMeasuresResult:
    """Table 1 measures of every object present in `state`, from the reconstructed points (mesh vertices).

    surface: optional (samples (N, 3), seen (N,) bool) of the true surface (reconstruction.observed_surface); each
    object row then gets `surface_seen_share`, the share of its true surface (bottom excluded) the cameras saw.
    """
    if not margin >= 0:
        raise ConfigError(f"expected a distance >= 0 m, got {margin}", parameter="margin")
    if not min_height >= 0:
        raise ConfigError(f"expected a distance >= 0 m, got {min_height}", parameter="min_height")
    if footprint not in FOOTPRINTS:
        raise ConfigError(f"expected one of {', '.join(FOOTPRINTS)}, got {footprint!r}", parameter="footprint")
    pts = np.asarray(points, dtype=np.float64)
    objects = ground_truth_objects(gt, state)
    settings = {"margin": margin, "min_height": min_height, "footprint": footprint, "state": state}
    if not objects and not gt.info.get("table"):  # a scene without tabletop objects (the synthetic room)
        none = np.full(4, np.nan)
        return ObjectMeasuresResult([], none, none, float("nan"), None, {}, {
            **settings, "table_plane": "none (the ground truth has no table and no objects to measure)"})
    truth_plane = table_plane_truth(gt)
    plane_source = "fitted"
    try:
        plane = fit_table_plane(pts, gt, objects)
    except RecordingError:
        plane, plane_source = truth_plane.copy(), "true (too few reconstructed table points to fit one)"
    height = pts @ plane[:3] + plane[3]
    rows, errs = [], {m: [] for m in MEASURES}
    for o in objects:
        sel = o.in_box(pts, margin, margin_z=margin + VERTICAL_SLACK) & (height > min_height)
        true = measure(o.vertices[(o.vertices @ truth_plane[:3] + truth_plane[3]) > -1e-6], truth_plane, footprint)
        row = {"id": o.id, "shape": o.shape, "points": int(np.count_nonzero(sel)), "true": true}
        if surface is not None:
            row["surface_seen_share"] = _seen_share(o, truth_plane, *surface)
        if row["points"] >= min_points:
            got = measure(pts[sel], plane, footprint)
            row["measured"] = got
            row["error"] = {m: got[m] - true[m] for m in MEASURES}
            for m in MEASURES:
                errs[m].append(row["error"][m])
        else:
            row["measured"] = None
            row["error"] = None
            row["note"] = f"fewer than {min_points} reconstructed points in its box: not measured"
        rows.append(row)
    pooled = np.concatenate([np.asarray(v, dtype=float) for v in errs.values()])
    per_measure = {m: {"mean_abs": float(np.mean(np.abs(v))) if v else None, "std": _std(v), "count": len(v)}
                   for m, v in errs.items()}
    return ObjectMeasuresResult(rows, plane, truth_plane, float(np.abs(pooled).mean()) if pooled.size else float("nan"),
                                _std(pooled), per_measure,
                                {**settings, "table_plane": plane_source})
