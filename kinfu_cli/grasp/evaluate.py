"""`kinfu eval grasp`: grasp poses on generated objects (the thesis' Table 7.2 sizes, and composite objects
for the multi-part problem) and on segmented synthetic tabletop scenes, checked independently of the
optimiser: from each reported pose, the L and V hand points' penetration of the support plane, of the
target's other parts, the cone angles and the workspace box are recomputed.

Time per object is CPU time (`time.process_time`, robust to a loaded machine) with, in the same process,
the time of a superquadric fit to a 200-point partial view as the reference (thesis Table 7.1: modelling
0.12-0.32 s, grasp 0.05-0.42 s per object).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from kinfu_cli.core.checks import check_number
from kinfu_cli.grasp.constraints import AXES, preset_cone
from kinfu_cli.grasp.plan import GraspOptions, ObjectGrasp, grasp_object, plan_grasps
from kinfu_cli.grasp.constraints import default_workspaces
from kinfu_cli.grasp.solve import CONSTRAINT_TOL, _f_pow
from kinfu_cli.segmentation.superquadric import Superquadric, arc_view_dirs, fit_superquadric, partial_view_cloud, \
    rpy_to_matrix

# Table 7.2 object sizes (m, full extents x, y, z)
TABLE_7_2 = {"cylinder": (0.06, 0.06, 0.20), "cat": (0.10, 0.10, 0.10), "bear": (0.09, 0.09, 0.12),
             "ladybug": (0.16, 0.08, 0.08), "lettuce": (0.07, 0.07, 0.07), "turtle": (0.16, 0.10, 0.06)}
SHAPES = {"box": (0.1, 0.1), "cylinder": (0.1, 1.0), "ellipsoid": (1.0, 1.0)}
THESIS_GRASP_S = (0.05, 0.42)
PLANE = np.array([0.0, 0.0, 1.0, 0.0])


def generated_objects(yaws: int = 2, seed: int = 0) -> list[tuple[str, list[Superquadric]]]:
    """Single superquadrics of every Table 7.2 size x shape (box, cylinder, ellipsoid) x `yaws` random yaws,
    resting on the plane z = 0 in front of the robot (x 0.3-0.5 m), and three composite objects."""
    rng = np.random.default_rng(seed)
    out = []
    for name, dims in TABLE_7_2.items():
        for shape, ex in SHAPES.items():
            for _ in range(yaws):
                a = np.asarray(dims) / 2
                c = np.array([rng.uniform(0.3, 0.5), rng.uniform(-0.15, 0.15), a[2]])
                out.append((f"{name}-{shape}", [Superquadric(a, np.array(ex), c, rpy_to_matrix([0, 0, rng.uniform(0, np.pi)]))]))
    return out + composite_objects(rng)


def composite_objects(rng: np.random.Generator) -> list[tuple[str, list[Superquadric]]]:
    """Multi-part objects with known parts: a bottle (body + neck), a T (bar on a post), an L (two boxes)."""
    def sq(a, ex, c, yaw=0.0):
        return Superquadric(np.asarray(a, float), np.asarray(ex, float), np.asarray(c, float), rpy_to_matrix([0, 0, yaw]))

    x, y, yaw = rng.uniform(0.3, 0.5), rng.uniform(-0.1, 0.1), rng.uniform(0, np.pi)
    R = rpy_to_matrix([0, 0, yaw])
    bottle = [sq((0.035, 0.035, 0.08), (0.1, 1.0), (x, y, 0.08)), sq((0.015, 0.015, 0.04), (0.1, 1.0), (x, y, 0.2))]
    t_shape = [sq((0.02, 0.02, 0.06), (0.1, 0.1), (x, y, 0.06), yaw),
               sq((0.09, 0.02, 0.02), (0.1, 0.1), (x, y, 0.14), yaw)]
    l_shape = [sq((0.08, 0.03, 0.02), (0.1, 0.1), np.array([x, y, 0.02]), yaw),
               sq((0.02, 0.03, 0.06), (0.1, 0.1), np.array([x, y, 0.0]) + R @ [0.06, 0, 0] + [0, 0, 0.10], yaw)]
    return [("bottle-2-parts", bottle), ("t-shape-2-parts", t_shape), ("l-shape-2-parts", l_shape)]


def check_grasp(o: ObjectGrasp, plane: np.ndarray | None, options: GraspOptions, workspaces: dict) -> dict:
    """Independent check of a reported grasp: penetrations (m, or obstacle F-sum) and whether every
    constraint holds within CONSTRAINT_TOL."""
    g = o.best
    if g is None:
        return {"converged": False, "satisfied": False}
    R, p = g.rotation, g.position
    pts = p + np.vstack([g.hand.l_points(), g.hand.v_points()]) @ R.T
    plane_pen = 0.0 if plane is None else float(max(0.0, -(pts @ plane[:3] + plane[3]).min()))
    cone_ok = all(R[:, AXES.index(c.axis)] @ c.unit() >= np.cos(np.radians(c.aperture_deg)) - CONSTRAINT_TOL
                  for c in options.cones)
    ws = workspaces[o.best_hand]
    ws_ok = bool(np.all(p >= np.asarray(ws.low) - 1e-9) and np.all(p <= np.asarray(ws.high) + 1e-9))
    V = p + g.hand.v_points() @ R.T
    obst_vals, inside, obst_pen = [], 0, 0.0
    for k, q in enumerate(o.parts):
        if k == o.best_part:
            continue
        f = np.sqrt(np.prod(q.size)) * _f_pow(V, q)  # eq. 8.2 per hand point
        obst_vals.append(float(f.min()))
        deep = f < -CONSTRAINT_TOL  # inside beyond the constraint tolerance (a point on the surface is outside)
        inside += int(np.sum(deep))
        if deep.any():  # depth (m) of the deepest palm / finger point inside the part, along its ray
            obst_pen = max(obst_pen, float(q.radial_distance(V[deep]).max()))
    obst_ok = all(v >= -CONSTRAINT_TOL for v in obst_vals)
    return {"converged": True, "satisfied": bool(plane_pen <= CONSTRAINT_TOL and cone_ok and ws_ok and obst_ok),
            "plane_penetration_m": plane_pen, "obstacle_constraint_min": min(obst_vals) if obst_vals else None,
            "hand_points_inside_obstacles": inside, "obstacle_penetration_m": obst_pen,
            "overlap_rms_m": g.overlap_rms, "cost": g.cost}


def _summary(rows: list[dict]) -> dict:
    conv = [r for r in rows if r["converged"]]
    out = {"objects": len(rows), "converged": len(conv), "converged_share": len(conv) / max(len(rows), 1),
           "satisfied_share": (sum(r["satisfied"] for r in conv) / len(conv)) if conv else None}
    if conv:
        ov = np.array([r["overlap_rms_m"] for r in conv])
        out.update({"overlap_rms_median_m": float(np.median(ov)), "overlap_rms_max_m": float(ov.max()),
                    "plane_penetration_max_m": float(max(r["plane_penetration_m"] for r in conv)),
                    "hand_points_inside_obstacles": int(sum(r["hand_points_inside_obstacles"] for r in conv)),
                    "obstacle_penetration_max_m": float(max(r["obstacle_penetration_m"] for r in conv))})
    cpu = np.array([r["cpu_seconds"] for r in rows])
    out.update({"cpu_s_median": float(np.median(cpu)), "cpu_s_p95": float(np.percentile(cpu, 95)),
                "cpu_s_max": float(cpu.max())})
    if rows and "reference_fit_cpu_s" in rows[0]:
        ref = np.array([r["reference_fit_cpu_s"] for r in rows])
        out["grasp_over_fit_time_ratio"] = float(np.median(cpu / ref))
    return out


def evaluate_generated(options: GraspOptions, conditions=("none", "top", "side"), yaws: int = 2, seed: int = 0,
                       progress=None) -> dict:
    """Every generated object under each cone condition; rows and per-condition summaries (single vs multi)."""
    objects = generated_objects(yaws, seed)
    rows = []
    work = [(c, n, parts) for c in conditions for n, parts in objects]
    for cond, name, parts in (progress(work) if progress else work):
        opts = replace(options, cones=[] if cond == "none" else [preset_cone(cond, PLANE[:3])])
        ws = default_workspaces(np.array([q.center for q in parts]), PLANE[:3])
        c0 = time.process_time()
        o = grasp_object(0, parts, PLANE, ws, opts)
        cpu = time.process_time() - c0
        row = {"object": name, "condition": cond, "parts": len(parts), "cpu_seconds": cpu, "hand": o.best_hand,
               **check_grasp(o, PLANE, opts, ws)}
        if len(parts) == 1:  # reference: a superquadric fit to a partial view of the same object, same process
            cloud = partial_view_cloud(parts[0], arc_view_dirs(np.pi), n=600, noise=0.002, rng=0)
            c0 = time.process_time()
            fit_superquadric(cloud)
            row["reference_fit_cpu_s"] = time.process_time() - c0
        rows.append(row)
    summ = {}
    for cond in conditions:
        for kind, sel in (("single", lambda r: r["parts"] == 1), ("multi", lambda r: r["parts"] > 1)):
            rs = [r for r in rows if r["condition"] == cond and sel(r)]
            if rs:
                summ[f"{cond}/{kind}"] = _summary(rs)
    return {"rows": rows, "summary": summ}


def segmented_scene(seed: int) -> dict:
    """segments.json of a generated tabletop scene (sim.scene primitives), segmented from its exact TSDF."""
    from kinfu_cli.segmentation.pipeline import analyse_cloud
    from kinfu_cli.segmentation.surface import surface_from_tsdf
    from kinfu_cli.sim.scene import primitive_tabletop_scene
    from kinfu_cli.sim.tsdf import scene_tsdf

    vs, origin = 0.006, np.array([-0.66, -0.46, 0.62])
    scene = primitive_tabletop_scene(seed)
    tsdf, w = scene_tsdf(scene, origin, vs, (220, 154, 60), box_min=(-0.66, -0.46, 0.62), box_max=(0.66, 0.46, 0.98))
    cloud = surface_from_tsdf(tsdf, w, origin, vs)
    return analyse_cloud(cloud.points, cloud.normals).to_json()


def evaluate_scenes(options: GraspOptions, seeds=(0, 1), progress=None) -> dict:
    """Grasps of every segment of the generated scenes, checked as the generated objects are."""
    rows, warnings = [], []
    for seed in (progress(list(seeds)) if progress else seeds):
        doc = segmented_scene(int(seed))
        res = plan_grasps(doc, options)
        warnings += [f"scene {seed}: {w}" for w in res.warnings]
        for o in res.objects:
            rows.append({"scene": int(seed), "object": f"segment {o.segment}", "parts": len(o.parts),
                         "cpu_seconds": o.cpu_seconds, "hand": o.best_hand,
                         **check_grasp(o, res.plane, options, res.workspaces)})
    return {"rows": rows, "summary": {"scenes": _summary(rows)} if rows else {}, "warnings": warnings}


def evaluate_grasping(options: GraspOptions | None = None, *, conditions=("none", "top", "side"), yaws: int = 2,
                      scenes=(0, 1), seed: int = 0, progress=None) -> dict:
    """The whole `kinfu eval grasp` document."""
    options = options or GraspOptions()
    options.validate()
    check_number(seed, "seed", 0, 2 ** 63 - 1, integer=True)  # numpy refuses negative seeds with a bare ValueError
    for s in scenes or ():
        check_number(s, "scenes", 0, 2 ** 63 - 1, integer=True)
    doc = {"generated": evaluate_generated(options, conditions, yaws, seed, progress),
           "scenes": evaluate_scenes(options, scenes, progress) if scenes else {"rows": [], "summary": {}},
           "hand": options.hand, "thesis": {"grasp_s_per_object": list(THESIS_GRASP_S), "target_s": 0.05,
                                            "target_satisfied_share": 1.0}}
    doc["warnings"] = list(doc["scenes"].get("warnings", []))
    return doc


def format_grasp_table(doc: dict) -> str:
    """The per-condition summary as a fixed-width table."""
    head = (f"{'set':<16}{'objects':>8}{'conv %':>8}{'sat %':>7}{'ovl med mm':>11}{'ovl max mm':>11}"
            f"{'plane pen mm':>13}{'in obst':>8}{'obst pen mm':>12}{'cpu med s':>10}{'cpu p95 s':>10}{'cpu max s':>10}"
            f"{'vs fit':>7}")
    lines = [head]
    for part in ("generated", "scenes"):
        for name, s in doc[part]["summary"].items():
            sat = "-" if s["satisfied_share"] is None else f"{100 * s['satisfied_share']:.0f}"
            lines.append(f"{name:<16}{s['objects']:>8}{100 * s['converged_share']:>8.0f}{sat:>7}"
                         f"{1000 * s.get('overlap_rms_median_m', np.nan):>11.1f}"
                         f"{1000 * s.get('overlap_rms_max_m', np.nan):>11.1f}"
                         f"{1000 * s.get('plane_penetration_max_m', np.nan):>13.2f}"
                         f"{s.get('hand_points_inside_obstacles', 0):>8}"
                         f"{1000 * s.get('obstacle_penetration_max_m', 0.0):>12.2f}{s['cpu_s_median']:>10.3f}"
                         f"{s.get('cpu_s_p95', np.nan):>10.3f}{s['cpu_s_max']:>10.3f}"
                         f"{s.get('grasp_over_fit_time_ratio', np.nan):>7.2f}")
    lines.append(f"thesis: {THESIS_GRASP_S[0]}-{THESIS_GRASP_S[1]} s per object (Table 7.1); target <= 0.05 s and "
                 f"100 % of the poses satisfying every constraint")
    return "\n".join(lines)
