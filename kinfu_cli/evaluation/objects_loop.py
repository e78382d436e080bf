"""Object-driven vs standard view planning in a closed loop (thesis ch. 3, Table 3.1 and Fig. 3.17).

From a short one-sided scan of a synth scene, each strategy picks `views` next-best views; each view is
rendered with the synth Kinect model and fused; after each view the unknown voxels within
`near_distance` of the true object surfaces are counted. Reported: that curve, candidate views ray-cast
and planning time per view. Both strategies use the same contour viewpoints and the NBV module's ray
caster (count of rays ending on unknown voxels); the standard one scores every candidate on the whole
environment, the object-driven one only the most salient segment's candidates on its sphere.
"""

from __future__ import annotations

import time

import numpy as np


def compare_strategies(seed: int = 0, *, views: int = 5, scan_frames: int = 8, score_px: int = 160,
                       resolution: int = 256, size: float = 1.6, near_distance: float = 0.05,
                       score_fraction: float = 0.01, strategies=("objects", "standard"), log=None) -> dict:
    """Thesis Fig. 3.17 / Table 3.1 in simulation: from a short one-sided scan, take `views` NBVs with the
    object-driven and the standard strategy (each view rendered with the synth sensor and fused), counting
    unknown voxels within 5 cm of the true object surfaces after each view, candidate views ray-cast and
    planning time. Views are scored with a `score_px`-wide image of the same field of view (both strategies);
    ScoreTH (not given in the thesis) is `score_fraction` of that image's pixels."""
    import open3d as o3d

    from kinfu_cli.fusion.volume import TernaryVolume
    from kinfu_cli.nbv.camera import CameraModel
    from kinfu_cli.nbv.contours import extract_contours
    from kinfu_cli.nbv.objects import nbv_scorer, plan_object_views, plan_standard_views
    from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume
    from kinfu_cli.sim.scenario import make_scenario

    sc = make_scenario(seed)
    scene = sc.scene_after
    c = np.array([scene.table.center[0], scene.table.center[1], scene.table.top_z])
    base = TernaryVolume(size=size, resolution=resolution, origin=c - np.array([size / 2, size / 2, 0.25]), color=False)
    for k, f in enumerate([f for f in sc.frames if f.phase == "scan"][:scan_frames]):
        depth, _ = sc.sensor.render(scene, f.T_world_camera, frame_seed=k)
        base.integrate(depth, sc.K, f.T_world_camera)
    # voxels near the objects: centres within 5 cm of a true object surface, above the table top
    grid0 = base.ternary_grid()
    rs = o3d.t.geometry.RaycastingScene()
    for o in scene.present_objects:
        rs.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(o.mesh))
    lo = np.min([o.center for o in scene.present_objects], axis=0) - 0.25
    hi = np.max([o.center for o in scene.present_objects], axis=0) + 0.25
    ilo = np.clip(grid0.index_of(lo[None])[0], 0, grid0.shape)
    ihi = np.clip(grid0.index_of(hi[None])[0] + 1, 0, grid0.shape)
    idx = np.stack(np.meshgrid(*[np.arange(a, b) for a, b in zip(ilo, ihi)], indexing="ij"), -1).reshape(-1, 3)
    cen = grid0.centers(idx)
    d = rs.compute_distance(o3d.core.Tensor(cen.astype(np.float32))).numpy()
    near = idx[(d <= near_distance) & (cen[:, 2] > scene.table.top_z + 0.005)]

    def unknown_near(vol) -> int:
        lab = vol.labels()
        return int(np.sum(lab[near[:, 0], near[:, 1], near[:, 2]] == 0))

    s = score_px / sc.width
    cam = CameraModel(fx=sc.K[0, 0] * s, fy=sc.K[1, 1] * s, cx=(sc.K[0, 2] + 0.5) * s - 0.5,
                      cy=(sc.K[1, 2] + 0.5) * s - 0.5, width=score_px, height=int(round(sc.height * s)),
                      min_range=0.3)
    out = {"near_voxels": int(len(near)), "unknown_near_initial": unknown_near(base)}
    score_th = score_fraction * cam.width * cam.height
    out["score_threshold"] = score_th
    for strategy in strategies:
        vol = base.copy()
        curve, cast, secs, scores = [], [], [], []
        for v in range(views):
            grid = vol.ternary_grid()
            scorer = nbv_scorer(grid, cam, table_z=float(scene.table.top_z))
            t = time.perf_counter()
            contours = extract_contours(grid.labels, grid.origin, grid.voxel_size)
            if strategy == "objects":
                segs = analyse_volume(vol, SegmentOptions(superquadrics=False))
                plan = plan_object_views(segs, contours, scorer, score_threshold=score_th)
            else:
                env_c = grid.origin + np.array(grid.shape) * grid.voxel_size / 2
                plan = plan_standard_views(contours, scorer, env_c,
                                           float(np.linalg.norm(np.array(grid.shape) * grid.voxel_size) / 2),
                                           score_threshold=score_th)
            secs.append(time.perf_counter() - t)
            cast.append(plan.candidates_evaluated)
            if plan.pose is None:
                break
            scores.append(plan.score)
            depth, _ = sc.sensor.render(scene, plan.pose, frame_seed=100 + v)
            vol.integrate(depth, sc.K, plan.pose)
            curve.append(unknown_near(vol))
        out[strategy] = {"unknown_near_after_each_view": curve, "candidates_cast": cast,
                         "candidates_cast_total": int(sum(cast)), "planning_seconds": secs,
                         "planning_seconds_total": float(sum(secs)), "scores": scores}
        if log is not None:
            log(strategy, out[strategy])
    if "objects" not in out or "standard" not in out:
        return out
    o, st = out["objects"], out["standard"]
    # same unknown-voxel reduction near objects: views the object strategy needs to reach the standard's end
    target = st["unknown_near_after_each_view"][-1] if st["unknown_near_after_each_view"] else out["unknown_near_initial"]
    k = next((i + 1 for i, u in enumerate(o["unknown_near_after_each_view"]) if u <= target), None)
    out["equal_reduction"] = None if k is None else {
        "unknown_near": target, "standard_views": len(st["unknown_near_after_each_view"]),
        "standard_cast": st["candidates_cast_total"], "objects_views": k,
        "objects_cast": int(sum(o["candidates_cast"][:k])),
        "cast_ratio": st["candidates_cast_total"] / max(int(sum(o["candidates_cast"][:k])), 1)}
    out["cast_ratio_standard_over_objects"] = st["candidates_cast_total"] / max(o["candidates_cast_total"], 1)
    out["time_ratio_standard_over_objects"] = st["planning_seconds_total"] / max(o["planning_seconds_total"], 1e-9)
    return out
