"""Text tables of `kinfu eval segment` (one evaluation, or the sweep), from the JSON-ready documents of
`evaluation.segment_eval`, so a saved results file can be printed again."""

from __future__ import annotations


def format_segment_table(doc: dict) -> str:
    """One segmentation against its ground truth: the thesis' measures, then per true object."""
    p = doc["points"]
    lines = [f"kinfu eval segment: {doc['input']['segments']} vs {doc['input']['ground_truth']} "
             f"(labels from {doc['input']['labels_from']})", "",
             f"points: {p['evaluated']} of {p['segmented']} segmented points scored ({p['unmatched']} with no "
             f"ground truth within {doc['max_distance'] * 100:.1f} cm); {p['ground_truth_unseen']} of "
             f"{p['ground_truth']} ground-truth points unseen ({p['ground_truth_unseen_share']:.0%}); boundary "
             f"matching: {_matching(doc)}", "",
             f"  {'T_eval':>7} {'bnd P':>6} {'bnd R':>6} {'bnd F':>6} {'BCE':>6} {'obj R':>6} {'found':>6} "
             f"{'segs':>5} {'over':>5} {'under':>5}",
             f"  {doc['t_eval'] * 100:5.1f}cm {doc['boundary_precision']:6.3f} {doc['boundary_recall']:6.3f} "
             f"{doc['boundary_f']:6.3f} {doc['bce']:6.3f} {doc['object_recall']:6.3f} "
             f"{doc['objects_found']:>3}/{doc['objects_total']:<2} {doc['segments']:5d} {doc['over_segmented']:5d} "
             f"{doc['under_segmenting']:5d}", "",
             f"  {'object':>16}  points  best segment  cover  found   (found: one segment holds >= "
             f"{doc['cover']:.0%} and it is that segment's majority)"]
    for o in doc["per_object"]:
        name = f"{o.get('name', o['object'])} ({o['object']})"
        lines.append(f"  {name[-16:]:>16} {o['points']:7d} {o['segment']:13d} {o['coverage']:6.2f}  "
                     f"{'yes' if o['found'] else 'no'}")
    for u in doc["under"]:
        lines.append(f"  under-segmentation: segment {u['segment']} holds >= {doc['share']:.0%} of true regions "
                     f"{u['objects']}")
    for o in doc["over"]:
        lines.append(f"  over-segmentation: object {o['object']} split over segments {o['segments']}")
    return "\n".join(lines)


def _matching(doc: dict) -> str:
    """The boundary matching of a results document; files written before it was recorded used the greedy one."""
    return doc.get("matching", "greedy")


def _scene_name(s: dict) -> str:
    return f"{s.get('layout', 'objects')} {s['seed']} {s.get('color', '')}".strip()


def format_sweep_table(doc: dict) -> str:
    """Per scene (layout, seed, colour mode) and threshold value: boundary P/R/F, BCE, object recall,
    over/under; then min BCE per scene (thesis Table 4.3) and the means over the scenes per colour mode."""
    name = doc["parameter"]
    sizes = doc["fusion"].get("sizes", {})
    lines = [f"kinfu eval segment, sweep: {name} ({doc.get('method', 'lccp')}) over {len(doc['values'])} values on "
             f"{len(doc['scenes'])} generated scene volumes (synth {', '.join(doc.get('layouts', ['objects']))} "
             f"seeds {', '.join(map(str, doc['seeds']))}; colour {', '.join(doc.get('colors', ['none']))}"
             f"{', photometric effects' if doc.get('photometric') else ''}; voxel "
             f"{doc['fusion'].get('voxel_m', 0) * 1000:.1f} mm, cubes "
             f"{', '.join(f'{k} {v} m' for k, v in sizes.items())}), T_eval {doc['t_eval'] * 100:.1f} cm, "
             f"boundary matching: {_matching(doc)}"
             f"{'; colour distance: ' + doc.get('color_distance', 'rgb') if name in ('t_lccp', 't_ff') else ''}", "",
             f"  {'scene':>16} {name[:12]:>12} {'bnd P':>6} {'bnd R':>6} {'bnd F':>6} {'BCE':>6} {'obj R':>6} "
             f"{'segs':>5} {'over':>5} {'under':>5}  missed"]
    for s in doc["scenes"]:
        for r in s["rows"]:
            lines.append(f"  {_scene_name(s):>16} {r['value']:12g} {r['boundary_precision']:6.3f} "
                         f"{r['boundary_recall']:6.3f} {r['boundary_f']:6.3f} {r['bce']:6.3f} {r['object_recall']:6.3f} "
                         f"{r['segments']:5d} {r['over_segmented']:5d} {r['under_segmenting']:5d}  "
                         f"{', '.join(map(str, r['missed']))}")
    lines += ["", "  minimum BCE per scene (thesis Table 4.3) and best boundary F:"]
    for s in doc["scenes"]:
        lines.append(f"  {_scene_name(s)}: min BCE {s['min_bce']:.3f}; best F {s['best_f']['boundary_f']:.3f} at "
                     f"{name} = {s['best_f']['value']:g}")
    lines += ["", f"  mean over scenes {'colour':>6} {name[:12]:>12} {'bnd P':>6} {'bnd R':>6} {'bnd F':>6} {'BCE':>6} "
                  f"{'obj R':>6}"]
    for c, m in doc["means"].items():
        for i, v in enumerate(doc["values"]):
            lines.append(f"  {'':16} {c:>6} {v:12g} {m['boundary_precision'][i]:6.3f} {m['boundary_recall'][i]:6.3f} "
                         f"{m['boundary_f'][i]:6.3f} {m['bce'][i]:6.3f} {m['object_recall'][i]:6.3f}")
    return "\n".join(lines)
