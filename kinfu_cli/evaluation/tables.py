"""Text tables of the evaluation results documents, as `kinfu eval fusion` and `kinfu eval nbv` print them.

Each function reads only the JSON-ready document its driver returned (`evaluate_fusion(...).document`,
`run_loop(...)`), so a saved results file can be printed again.
"""

from __future__ import annotations

import math


def _mm(x) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "   -  "
    return f"{x * 1000:6.1f}"


def format_fusion_tables(doc: dict) -> str:
    """The human-readable tables (millimetres; Table 1 in metres like the paper)."""
    r = doc["reconstruction"]
    a, c = r["accuracy"], r["completeness_distances"]
    lines = [f"kinfu eval fusion: {doc['input']['reconstruction']} vs {doc['input']['ground_truth']} "
             f"({doc['input']['state']} state, {r['frames']} true camera poses)", "",
             "Reconstruction error (mm)      mean  median     RMS     p95     max       n",
             f"  accuracy (recon -> true) {_mm(a['mean'])}  {_mm(a['median'])}  {_mm(a['rms'])}  {_mm(a['p95'])}  "
             f"{_mm(a['max'])}  {a['count']:6d}",
             f"  completeness (true -> rec){_mm(c['mean'])}  {_mm(c['median'])}  {_mm(c['rms'])}  {_mm(c['p95'])}  "
             f"{_mm(c['max'])}  {c['count']:6d}",
             f"  within {r['threshold'] * 1000:.0f} mm: precision {r['precision']:.3f}  completeness "
             f"{r['completeness']:.3f}  F-score {r['fscore']:.3f}  (observed true surface: {r['samples_observed']} "
             f"samples every ~{r['spacing'] * 1000:.0f} mm)"]
    v = r.get("volume")
    if v:
        cnt = v["counts"]
        share = v["visible_surface_known_share"]
        lines += ["", f"Volume {'x'.join(map(str, v['shape']))} at {v['voxel_size'] * 1000:.2f} mm: occupied "
                      f"{cnt['occupied']}, empty {cnt['empty']}, unknown {cnt['unknown']} "
                      f"({v['unknown_share'] * 100:.1f} % unknown)",
                  f"  true surface observed (voxel known): {share * 100 if share is not None else float('nan'):.1f} % "
                  f"of the visible surface, {(v['surface_in_grid_known_share'] or 0) * 100:.1f} % of all true "
                  f"surface in the grid"]
    o = doc["objects"]
    lines += ["", "Objects (mm)   shape      points   height true/err    major true/err    minor true/err   seen"]
    for row in o["objects"]:
        t, e = row["true"], row["error"] or {}
        seen = row.get("surface_seen_share")
        lines.append(f"  {row['id']:<12} {row['shape']:<9} {row['points']:6d}   {_mm(t['height'])} {_mm(e.get('height'))}"
                     f"    {_mm(t['major'])} {_mm(e.get('major'))}    {_mm(t['minor'])} {_mm(e.get('minor'))}"
                     + (f"   {seen * 100:3.0f} %" if seen is not None else "      -")
                     + ("   (not measured)" if row["error"] is None else ""))
    lines.append("  (seen: share of the object's true surface, bottom excluded, visible from the true camera poses)")
    pl = o["table_plane"]
    if pl.get("source", "fitted") == "fitted":
        lines.append(f"  table plane fit: tilt {pl['tilt_deg']:.2f} deg, offset {pl['offset'] * 1000:+.1f} mm")
    else:
        lines.append(f"  table plane: {pl['source']}")
    lines += ["", "Table 1 (Monica et al. RAS 2016): 3D object reconstruction errors (height, major and minor axis)",
              "  scenario   tracking                   mean abs. (m)   st. dev. (m)"]
    for row in doc["table_1"]:
        ma = "-" if row["mean_abs"] is None or not math.isfinite(row["mean_abs"]) else f"{row['mean_abs']:.3f}"
        sd = "-" if row["std"] is None or not math.isfinite(row["std"]) else f"{row['std']:.3f}"
        n = (f"   ({row['objects_measured']}/{row['objects_total']} objects measured)"
             if "objects_measured" in row else "")
        lines.append(f"  {str(row['scenario']):<10} {row['tracking']:<26} {ma:>13}   {sd:>12}{n}")
    return "\n".join(lines)


def exploration_table(doc: dict) -> list[str]:
    """The `run_exploration` result as text: unknown voxels near objects after each view, candidate views
    ray-cast and planning time per view, and the object-driven vs standard comparison."""
    runs = doc["strategies"]
    near = doc["near_objects"]
    nmax = max((len(r["unknown_near"]) for r in runs.values()), default=1)
    lines = [f"unknown voxels near objects (true bounding spheres + {near['margin_m']:g} m, {near['voxels']} voxels) "
             "after each view (v0 = after the initial scan)",
             f"{'strategy':10s} " + " ".join(f"{'v' + str(i):>7s}" for i in range(nmax)) + "  reduction"]
    for name, r in runs.items():
        u = r["unknown_near"]
        cells = " ".join(f"{int(x):7d}" for x in u) + " " * (8 * (nmax - len(u)))
        lines.append(f"{name:10s} {cells}  {(u[0] - u[-1]) / u[0] if u[0] else 0.0:9.1%}")
    lines.append("candidate views ray-cast per view (planning seconds)")
    for name, r in runs.items():
        cells = " ".join(f"{c}({t:.1f}s)" for c, t in zip(r["candidates_cast"], r["planning_seconds"]))
        lines.append(f"{name:10s} {cells}  total {r['candidates_cast_total']} ({r['planning_seconds_total']:.1f} s)")
    eq = doc.get("equal_reduction")
    if eq:
        ratio = "-" if eq["cast_ratio"] is None else f"{eq['cast_ratio']:.1f}x"
        tr = "-" if eq["time_ratio"] is None else f"{eq['time_ratio']:.1f}x"
        lines.append(f"same reduction ({eq['reduction_fraction']:.1%}, down to {eq['unknown_near']} unknown): "
                     f"objects {eq['objects_views']} views / {eq['objects_cast']} cast, standard "
                     f"{eq['standard_views']} views / {eq['standard_cast']} cast: {ratio} fewer cast views, "
                     f"{tr} less planning time")
    lines.append("time per stage (s): " + ", ".join(f"{k} {v:.2f}" for k, v in doc["time_s"].items()))
    return lines


def nbv_loop_table(doc: dict) -> list[str]:
    """Unknown voxels in each POI sphere after each view (the paper's Fig. 20 as a table), one row per
    strategy and POI, with views until IncTh, and the final error of each strategy."""
    if doc.get("kind") == "exploration":
        return exploration_table(doc)
    runs = doc["strategies"]
    nmax = max((len(v) for r in runs.values() for v in r["unknown"].values()), default=1)
    lines = ["unknown voxels in each POI sphere after each view (v0 = before the first view of that POI)",
             f"{'strategy':14s} {'POI':>3s} " + " ".join(f"{'v' + str(i):>7s}" for i in range(nmax)) + "  until-IncTh"]
    for name, r in runs.items():
        for pid, v in r["unknown"].items():
            u = r["views_until_incth"].get(pid)
            cells = " ".join(f"{int(x):7d}" for x in v) + " " * (8 * (nmax - len(v)))
            lines.append(f"{name:14s} {pid:>3s} {cells}  {'-' if u is None else u:>11}")
    lines.append(f"{'strategy':14s} {'views':>5s} {'frames':>6s} {'accuracy':>9s} {'precision':>9s} "
                 f"{'complete':>8s} {'s/view':>6s}")
    for name, r in runs.items():
        e = r["error"]
        acc = "-" if e.get("accuracy_mean_m") is None else f"{e['accuracy_mean_m'] * 1000:.1f}mm"
        prec = "-" if e.get("precision") is None else f"{e['precision']:.3f}"
        comp = "-" if e.get("completeness") is None else f"{e['completeness']:.3f}"
        lines.append(f"{name:14s} {sum(r['views_taken'].values()):5d} {r['frames_fused']:6d} {acc:>9s} {prec:>9s} "
                     f"{comp:>8s} {r['seconds_per_view']:6.2f}")
    lines.append("time per stage (s): " + ", ".join(f"{k} {v:.2f}" for k, v in doc["time_s"].items()))
    return lines
