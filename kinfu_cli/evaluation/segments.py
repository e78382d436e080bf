"""Segmentation against ground-truth object labels (thesis ch. 4.3 protocol, adapted to clouds).

- Boundary precision / recall at T_eval = 2 cm: B_N = points with a neighbour (closer than T_eval) of
  another label; the boundary B = for each b in B_N the nearest point of another label (eq. 4.16). B
  and the ground truth's B_GT are matched one-to-one, pairs farther than T_eval discarded; matches are true
  positives. The thesis' "(approximate) minimum distance assignment" follows Martin et al.'s boundary
  benchmark, whose assignment leaves a point unmatched only at a cost of 100 x T_eval: an augmenting path of
  fewer than 200 pairs always pays, so its matches are a maximum matching within T_eval, which is what
  `matching="assignment"` counts (Hopcroft-Karp). `matching="greedy"` (closest pairs first, the scorer before
  2026-11-26) undercounts where two boundaries run side by side one point apart.
- Object-level recall: a true object counts as found when one segment holds >= `cover` (80 %) of its
  points and that object is the segment's majority (so one segment swallowing two objects finds
  at most one of them).
- Bidirectional Consistency Error (Martin 2003, thesis ch. 4.1.2): per point p, E(S1, S2, p) =
  |R(S1, p) minus R(S2, p)| / |R(S1, p)| with R(S, p) the region of S holding p; BCE = mean over points of
  max(E(S, G, p), E(G, S, p)), 0 = identical, 1 = worst. A point the segmentation dropped (-1) is a region
  of its own.
- Over-/under-segmentation (with `share`, 20 %): a true object (table excluded) is over-segmented when two
  or more segments each hold >= share of its points; a segment under-segments when it holds >= share of
  the points of two or more true regions (table included: an object merged into the support plane).
- Ground-truth labels for a cloud: nearest ground-truth mesh (`objects/<id>.ply`, `table.ply`) within
  a distance, with open3d's RaycastingScene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.point_pairs import bounded_pairs, check_pair_count
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume
from kinfu_cli.sim.scenario import make_scenario
from kinfu_cli.sim.scene import Scene


T_EVAL_HINT = "expected the boundary tolerance T_eval of a few centimetres (default 0.02 m)"


def boundary_set(points: np.ndarray, labels: np.ndarray, t_eval: float = 0.02) -> np.ndarray:
    """Indices of the boundary B (eq. 4.16) of a labelling. Its pair search is bounded (core.point_pairs): a
    t_eval spanning the cloud is a ConfigError naming t_eval, not a search that runs out of memory."""
    pts = np.asarray(points, dtype=np.float64)
    lab = np.asarray(labels)
    pairs = bounded_pairs(pts, t_eval, what="points scored", parameter="t_eval", hint=T_EVAL_HINT)
    if len(pairs) == 0:
        return np.zeros(0, dtype=np.int64)
    diff = lab[pairs[:, 0]] != lab[pairs[:, 1]]
    p = pairs[diff]
    if len(p) == 0:
        return np.zeros(0, dtype=np.int64)
    # nearest point of another label for each b in B_N: among its cross-label pairs, the closest
    i = np.concatenate([p[:, 0], p[:, 1]])
    j = np.concatenate([p[:, 1], p[:, 0]])
    d = np.linalg.norm(pts[i] - pts[j], axis=1)
    order = np.lexsort((d, i))
    i, j = i[order], j[order]
    first = np.r_[True, i[1:] != i[:-1]]
    return np.unique(j[first])


MATCHINGS = ("assignment", "greedy")


def match_boundaries(points: np.ndarray, b_pred: np.ndarray, b_gt: np.ndarray, t_eval: float = 0.02,
                     matching: str = "assignment") -> int:
    """Number of one-to-one matches within t_eval between two boundary index sets: the maximum ("assignment",
    module docstring) or closest pairs first ("greedy")."""
    if matching not in MATCHINGS:
        raise ConfigError(f"expected one of {', '.join(MATCHINGS)}, got {matching!r}", parameter="matching")
    if len(b_pred) == 0 or len(b_gt) == 0:
        return 0
    A = cKDTree(points[b_pred])
    B = cKDTree(points[b_gt])
    check_pair_count(B, t_eval, queries=points[b_pred], what="ground-truth boundary points", parameter="t_eval",
                     hint=T_EVAL_HINT)  # the (predicted, true) boundary pairs the matrix holds
    sdm = A.sparse_distance_matrix(B, t_eval, output_type="ndarray")
    if len(sdm) == 0:
        return 0
    if matching == "assignment":
        graph = coo_matrix((np.ones(len(sdm)), (sdm["i"], sdm["j"])), shape=(len(b_pred), len(b_gt))).tocsr()
        return int(np.sum(maximum_bipartite_matching(graph, perm_type="column") >= 0))
    sdm = np.sort(sdm, order="v")
    used_a = np.zeros(len(b_pred), dtype=bool)
    used_b = np.zeros(len(b_gt), dtype=bool)
    tp = 0
    for a, b in zip(sdm["i"], sdm["j"]):  # greedy assignment over candidate pairs (not over points/voxels)
        if not used_a[a] and not used_b[b]:
            used_a[a] = used_b[b] = True
            tp += 1
    return tp


def consistency_errors(labels: np.ndarray, gt_labels: np.ndarray) -> np.ndarray:
    """Per-point max(E(S, G, p), E(G, S, p)) of `labels` against `gt_labels` (same points; -1 in `labels` =
    dropped, each such point a region of its own)."""
    lab = np.asarray(labels).astype(np.int64).ravel()
    gt = np.asarray(gt_labels).astype(np.int64).ravel()
    if len(lab) != len(gt):
        raise ConfigError(f"consistency error: {len(lab)} labels but {len(gt)} ground-truth labels")
    if len(lab) == 0:
        return np.zeros(0)
    drop = lab < 0
    lab = lab.copy()
    lab[drop] = lab.max(initial=0) + 1 + np.arange(int(drop.sum()))
    _, s_inv, s_cnt = np.unique(lab, return_inverse=True, return_counts=True)
    _, g_inv, g_cnt = np.unique(gt, return_inverse=True, return_counts=True)
    cells, cell_inv, n_sg = np.unique(np.stack([s_inv.ravel(), g_inv.ravel()], axis=1), axis=0,
                                      return_inverse=True, return_counts=True)
    s_size, g_size = s_cnt[cells[:, 0]], g_cnt[cells[:, 1]]
    err = np.maximum((s_size - n_sg) / s_size, (g_size - n_sg) / g_size)
    return err[cell_inv.ravel()]


def consistency_error(labels: np.ndarray, gt_labels: np.ndarray) -> float:
    """Bidirectional Consistency Error: the mean of `consistency_errors` (0 for no points)."""
    e = consistency_errors(labels, gt_labels)
    return float(e.mean()) if len(e) else 0.0


def segmentation_counts(labels: np.ndarray, gt_labels: np.ndarray, object_ids, share: float = 0.2,
                        min_object_points: int = 20) -> dict:
    """Over-segmented true objects and under-segmenting segments (module docstring), with who is involved."""
    lab = np.asarray(labels).ravel()
    gt = np.asarray(gt_labels).ravel()
    segs, s_inv = np.unique(lab, return_inverse=True)
    gts, g_inv = np.unique(gt, return_inverse=True)
    table = np.zeros((len(segs), len(gts)), dtype=np.int64)
    np.add.at(table, (s_inv.ravel(), g_inv.ravel()), 1)
    table[segs < 0] = 0  # dropped points are no segment
    frac = table / np.maximum(table.sum(axis=0, keepdims=True), 1)  # share of each true region per segment
    big = frac >= share
    over = []
    for oid in object_ids:
        col = np.flatnonzero(gts == oid)
        if len(col) and table[:, col[0]].sum() >= min_object_points and big[:, col[0]].sum() >= 2:
            over.append({"object": int(oid), "segments": [int(v) for v in segs[big[:, col[0]]]]})
    counted = np.asarray([g for g in gts if g >= 0 and table[:, gts == g].sum() >= min_object_points], dtype=gts.dtype)
    cols = np.isin(gts, counted)
    under = [{"segment": int(segs[i]), "objects": [int(v) for v in gts[cols & big[i]]]}
             for i in np.flatnonzero((big[:, cols]).sum(axis=1) >= 2)]
    return {"over_segmented": len(over), "under_segmenting": len(under), "over": over, "under": under,
            "share": share}


@dataclass
class SegmentationScore:
    boundary_precision: float
    boundary_recall: float
    boundary_pred: int
    boundary_gt: int
    object_recall: float
    objects_found: int
    objects_total: int
    per_object: list
    bce: float = float("nan")
    over_segmented: int = 0  # true objects split into >= 2 pieces of >= `share` each
    under_segmenting: int = 0  # segments holding >= `share` of >= 2 true regions
    segments: int = 0  # predicted segments (dropped points excluded)
    details: dict | None = None  # which objects / segments are over- / under-segmented

    def to_json(self) -> dict:
        return dict(self.__dict__)


def score_segmentation(points: np.ndarray, labels: np.ndarray, gt_labels: np.ndarray, *, t_eval: float = 0.02,
                       cover: float = 0.8, object_ids=None, min_object_points: int = 20,
                       ignore_gt: int | None = None, share: float = 0.2,
                       matching: str = "assignment") -> SegmentationScore:
    """Score predicted `labels` against `gt_labels` (same points). object_ids: true objects to count
    (default: every gt label except 0 = table and -1 = unlabelled) with >= min_object_points points;
    share: the piece size of the over- / under-segmentation counts; matching: of the boundaries (MATCHINGS)."""
    pts = np.asarray(points, dtype=np.float64)
    lab = np.asarray(labels)
    gt = np.asarray(gt_labels)
    if not (len(pts) == len(lab) == len(gt)):
        raise ConfigError(f"score: {len(pts)} points, {len(lab)} labels, {len(gt)} ground-truth labels differ")
    keep = np.ones(len(pts), dtype=bool) if ignore_gt is None else gt != ignore_gt
    pts, lab, gt = pts[keep], lab[keep], gt[keep]
    b_pred = boundary_set(pts, lab, t_eval)
    b_gt = boundary_set(pts, gt, t_eval)
    tp = match_boundaries(pts, b_pred, b_gt, t_eval, matching)
    prec = tp / len(b_pred) if len(b_pred) else 1.0
    rec = tp / len(b_gt) if len(b_gt) else 1.0
    if object_ids is None:
        object_ids = [int(v) for v in np.unique(gt) if v not in (0, -1)]
    # majority true object of each predicted segment
    segs, seg_inv = np.unique(lab, return_inverse=True)
    gts, gt_inv = np.unique(gt, return_inverse=True)
    table = np.zeros((len(segs), len(gts)), dtype=np.int64)
    np.add.at(table, (seg_inv.ravel(), gt_inv.ravel()), 1)
    majority = gts[np.argmax(table, axis=1)]
    per = []
    found = 0
    total = 0
    for oid in object_ids:
        col = np.flatnonzero(gts == oid)
        if len(col) == 0 or table[:, col[0]].sum() < min_object_points:
            continue
        total += 1
        c = table[:, col[0]]
        best = int(np.argmax(c))
        frac = float(c[best] / c.sum())
        ok = frac >= cover and majority[best] == oid and segs[best] != -1
        found += int(ok)
        per.append({"object": int(oid), "points": int(c.sum()), "segment": int(segs[best]), "coverage": frac,
                    "found": bool(ok)})
    counts = segmentation_counts(lab, gt, object_ids, share, min_object_points)
    return SegmentationScore(float(prec), float(rec), int(len(b_pred)), int(len(b_gt)),
                             float(found / total) if total else 1.0, found, total, per,
                             consistency_error(lab, gt), counts["over_segmented"], counts["under_segmenting"],
                             int(np.sum(segs >= 0)), counts)


def gt_labels_from_meshes(points: np.ndarray, meshes: dict[int, object], max_distance: float = 0.015
                          ) -> np.ndarray:
    """Label of the nearest ground-truth mesh per point (-1 beyond `max_distance`)."""
    pts = o3d.core.Tensor(np.asarray(points, dtype=np.float32))
    ids = sorted(meshes)
    dist = np.full((len(points), len(ids)), np.inf, dtype=np.float64)
    for k, oid in enumerate(ids):
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(meshes[oid]))
        dist[:, k] = scene.compute_distance(pts).numpy()
    best = np.argmin(dist, axis=1)
    lab = np.asarray(ids)[best]
    return np.where(dist[np.arange(len(points)), best] <= max_distance, lab, -1)


# The simulator's photometric effects used for the colour comparisons (as benchmarks/bench_color_mode.py):
# per-frame auto-gain, white-balance drift and colour-depth misregistration, the blur the mode filter is for.
PHOTOMETRIC = {"gain_jitter": 0.15, "white_balance_jitter": 0.04, "misregistration": (1.5, -1.0, 0.3)}
COLOR_CHOICES = ("none", "mean", "mode")  # "none": fused without colour (segmentation by shape alone)


def fuse_synthetic_volumes(seed: int = 0, *, colors=("none",), resolution: int = 256, size: float = 1.6,
                           width: int = 320, height: int = 240, frames: int = 36, noise: bool = True,
                           layout: str = "tabletop", photometric: bool | dict = False
                           ) -> tuple[dict[str, TernaryVolume], Scene]:
    """Fuse the after-change state of the synth scenario `seed` (layout: `make_scenario`'s) from all its
    camera poses, once per colour mode in `colors` (COLOR_CHOICES) from the same rendered images.
    photometric: render with PHOTOMETRIC (else the sensor's clean colours); a dict replaces some of its entries
    (e.g. {"misregistration": (0, 0, 0)}: is an effect due to the misregistration?).

    Returns ({colour mode: volume}, scene after the change).
    """
    from kinfu_cli.sim.sensor import DepthSensor

    bad = [c for c in colors if c not in COLOR_CHOICES]
    if bad or not colors:
        raise ConfigError(f"expected colour modes among {', '.join(COLOR_CHOICES)}, got {list(colors)}",
                          parameter="colors")
    sc = make_scenario(seed, width=width, height=height, frames=frames, noise=noise, layout=layout)
    after = sc.scene_after
    effects = PHOTOMETRIC | (photometric if isinstance(photometric, dict) else {})
    sensor = DepthSensor(sc.K, width, height, noise=noise, seed=seed, **effects) if photometric else sc.sensor
    c = np.array([after.table.center[0], after.table.center[1], after.table.top_z])
    vols = {m: TernaryVolume(size=size, resolution=resolution, origin=c - np.array([size / 2, size / 2, 0.25]),
                             color=m != "none", color_mode="mean" if m == "none" else m) for m in dict.fromkeys(colors)}
    for k, f in enumerate(sc.frames):
        depth, rgb = sensor.render(after, f.T_world_camera, frame_seed=k)
        for m, vol in vols.items():
            vol.integrate(depth, sc.K, f.T_world_camera, None if m == "none" else rgb)
    return vols, after


def fuse_synthetic_scene(seed: int = 0, *, resolution: int = 256, size: float = 1.6, width: int = 320,
                         height: int = 240, frames: int = 36, noise: bool = True, layout: str = "tabletop",
                         color: str = "none", photometric: bool = False) -> tuple[TernaryVolume, Scene]:
    """`fuse_synthetic_volumes` for one colour mode ("none" = without colour, "mean", "mode").

    Returns (volume, scene after the change).
    """
    vols, after = fuse_synthetic_volumes(seed, colors=(color,), resolution=resolution, size=size, width=width,
                                         height=height, frames=frames, noise=noise, layout=layout,
                                         photometric=photometric)
    return vols[color], after


def scene_gt_labels(points: np.ndarray, scene: Scene, max_distance: float = 0.015) -> tuple[np.ndarray, dict[int, str]]:
    """Ground-truth label per point: 0 for table and floor, 1.. for the present objects (nearest mesh)."""
    meshes = {0: scene.table.mesh()}
    names = {0: "table"}
    if scene.floor:
        meshes[-2] = scene.floor_mesh()
    for k, o in enumerate(scene.present_objects, start=1):
        meshes[k] = o.mesh
        names[k] = o.id
    lab = gt_labels_from_meshes(points, meshes, max_distance)
    lab[lab == -2] = 0
    return lab, names


def evaluate_synthetic_scenes(seeds=(0, 1, 2), *, resolution: int = 256, size: float = 1.6, options=None,
                              t_eval: float = 0.02) -> dict:
    """Segmentation of fused synth scenes vs their object meshes: boundary P/R at t_eval, object recall."""
    options = options or SegmentOptions(superquadrics=False)
    rows = []
    for seed in seeds:
        vol, scene = fuse_synthetic_scene(seed, resolution=resolution, size=size)
        res = analyse_volume(vol, options)
        gt, names = scene_gt_labels(res.segmentation.points, scene)
        sc = score_segmentation(res.segmentation.points, res.segmentation.labels, gt, t_eval=t_eval, ignore_gt=-1)
        for o in sc.per_object:
            o["name"] = names.get(o["object"], str(o["object"]))
        rows.append({"seed": seed, **sc.to_json(), "segments": len(res.saliency),
                     "shapes": [o.shape for o in scene.present_objects]})
    n_found = sum(r["objects_found"] for r in rows)
    n_total = sum(r["objects_total"] for r in rows)
    return {"scenes": rows, "object_recall": n_found / n_total if n_total else 1.0,
            "boundary_precision": float(np.mean([r["boundary_precision"] for r in rows])),
            "boundary_recall": float(np.mean([r["boundary_recall"] for r in rows]))}
