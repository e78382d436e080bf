"""Shape prior (thesis 7.3) accuracy: held-out generated primitives (a seed the packaged training set did not
use) and the segments of the synthetic scenes (ground-truth object labels of kinfu_cli.sim scenes: boxes,
cylinders, spheres, cones, tori, mugs); plus the size error of the fit with and without the prior's bounds
on partial views of known primitives.

    PYTHONPATH=$PWD python benchmarks/bench_shape_prior.py [n_per_kind] [n_scenes] [n_size]
    PYTHONPATH=$PWD python benchmarks/bench_shape_prior.py pipeline [n_scenes]   # inside kinfu segment
    PYTHONPATH=$PWD python benchmarks/bench_shape_prior.py forest    # numpy Forest vs scikit-learn, one process
"""

import sys

import numpy as np

from kinfu_cli.segmentation import shape_prior as sp
from kinfu_cli.segmentation.shape_samples import primitive_cloud, random_primitive_dims
from kinfu_cli.segmentation.superquadric import fit_superquadric
from kinfu_cli.sim.scene import make_tabletop_scene, primitive_tabletop_scene, scene_label_cloud, segmentation_scene

SCENE_CLASS = {"box": "box", "cylinder": "cylinder", "sphere": "sphere", "cone": "generic", "torus": "generic",
               "mug": "generic"}


def confusion(true: list[str], pred: list[str]) -> str:
    rows = ["true \\ pred " + " ".join(f"{c:>8}" for c in sp.CLASSES)]
    for t in sp.CLASSES:
        rows.append(f"{t:12} " + " ".join(f"{sum(1 for a, b in zip(true, pred) if a == t and b == p):8d}"
                                         for p in sp.CLASSES))
    return "\n".join(rows)


def held_out(n_per_kind: int) -> None:
    X, y = sp.training_set(n_per_kind, seed=12345)
    pred = sp.load_classifier().predict(X)
    true = [sp.CLASSES[i] for i in y]
    got = [sp.CLASSES[i] for i in pred]
    print(f"held-out generated primitives: {np.mean(pred == y):.3f} accuracy on {len(y)} shapes")
    print(confusion(true, got))


def scenes(n_scenes: int) -> None:
    true, got = [], []
    builders = [make_tabletop_scene, primitive_tabletop_scene, segmentation_scene]
    for seed in range(n_scenes):
        for build in builders:
            scene = build(seed=100 + seed)
            pts, lab = scene_label_cloud(scene, spacing=0.004, seed=seed)
            for o in scene.present_objects:
                seg = pts[lab == scene.label_of(o.id)]
                if o.shape not in SCENE_CLASS or len(seg) < sp.MIN_POINTS:
                    continue
                true.append(SCENE_CLASS[o.shape])
                got.append(sp.classify_shape(seg)[0])
    acc = np.mean([a == b for a, b in zip(true, got)])
    print(f"synthetic scene segments (ground-truth labels): {acc:.3f} accuracy on {len(true)} segments")
    print(confusion(true, got))


def true_extents(kind: str, dims: dict) -> np.ndarray:
    if kind == "box":
        return np.sort(dims["extents"])
    if kind == "cylinder":
        return np.sort([2 * dims["radius"], 2 * dims["radius"], dims["height"]])
    return np.full(3, 2 * dims["radius"])


def prior_size_error(n: int, partial: bool) -> None:
    """Max relative extent error of the fit, free vs with the prior (as `kinfu segment` applies it), on known
    primitives (random pose)."""
    from kinfu_cli.segmentation.pipeline import SegmentOptions, _fit_one

    rng = np.random.default_rng(4242)
    print(f"{'partial views' if partial else 'full surfaces'}: max relative extent error")
    print("kind      free fit median/p90   with prior median/p90   class correct")
    for kind in ("box", "cylinder", "sphere"):
        free, prior, ok = [], [], 0
        for _ in range(n):
            dims = random_primitive_dims(kind, rng)
            pts = primitive_cloud(kind, rng, partial=partial, dims=dims)
            truth = true_extents(kind, dims)
            f = fit_superquadric(pts)
            g, c = _fit_one(pts, SegmentOptions())
            ok += c.name == kind
            free.append(np.max(np.abs(np.sort(2 * f.superquadric.size) - truth) / truth))
            prior.append(np.max(np.abs(np.sort(2 * g.superquadric.size) - truth) / truth))
        print(f"{kind:9} {np.median(free):8.3f} / {np.percentile(free, 90):.3f}     "
              f"{np.median(prior):8.3f} / {np.percentile(prior, 90):.3f}        {ok}/{n}")


def scene_segments(build, seed: int, voxel: float = 0.006):
    """The segments `kinfu segment`'s pipeline finds on the exact TSDF of a generated scene (superquadrics off),
    and per object that one segment holds mostly (>= 80 % of the segment's points, the object's largest
    segment): [(object, segment points)]."""
    from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_cloud
    from kinfu_cli.segmentation.surface import surface_from_tsdf
    from kinfu_cli.sim.tsdf import scene_tsdf

    scene = build(seed=seed)
    t = scene.table
    lo = np.array([t.center[0] - t.size[0] / 2 - 0.1, t.center[1] - t.size[1] / 2 - 0.1, t.top_z - 0.1])
    hi = np.array([t.center[0] + t.size[0] / 2 + 0.1, t.center[1] + t.size[1] / 2 + 0.1, t.top_z + 0.35])
    shape = np.ceil((hi - lo) / voxel).astype(int) + 1
    tsdf, w = scene_tsdf(scene, lo, voxel, shape)
    cloud = surface_from_tsdf(tsdf, w, lo, voxel)
    res = analyse_cloud(cloud.points, cloud.normals, SegmentOptions(superquadrics=False))
    seg = res.segmentation
    truth = scene.nearest_labels(seg.points, max_distance=0.01)
    out = []
    for o in scene.present_objects:
        lab = scene.label_of(o.id)
        ids, counts = np.unique(seg.labels[(truth == lab) & (seg.labels > 0)], return_counts=True)
        if not len(ids):
            continue
        sid = ids[np.argmax(counts)]
        pts = seg.points[seg.labels == sid]
        if np.mean(truth[seg.labels == sid] == lab) >= 0.8 and len(pts) >= sp.MIN_POINTS:
            out.append((o, pts))
    return out


def pipeline_prior(n_scenes: int) -> None:
    """Shape prior inside `kinfu segment` (pipeline segments, not ground-truth labels): class accuracy, and the
    max relative extent error of the segment's superquadric against the object's true extents, without the
    prior (free exponents in [0.1, 1.9]) and with it (the class's eq. 7.11 bounds)."""
    from kinfu_cli.segmentation.pipeline import SegmentOptions, _fit_one

    rows = []
    for seed in range(n_scenes):
        for build in (primitive_tabletop_scene, make_tabletop_scene, segmentation_scene):
            for o, pts in scene_segments(build, 200 + seed):
                truth = np.sort(o.size)
                errs, cls = [], None
                for on in (False, True):
                    fit, c = _fit_one(pts, SegmentOptions(shape_prior=on))
                    cls = c.name if c is not None else cls
                    errs.append(float(np.max(np.abs(np.sort(2 * fit.superquadric.size) - truth) / truth)))
                rows.append((o.shape, SCENE_CLASS.get(o.shape, "generic"), cls, *errs))
    true = [r[1] for r in rows]
    got = [r[2] for r in rows]
    print(f"pipeline segments of synthetic scenes (seeds 200-{199 + n_scenes}): class accuracy "
          f"{np.mean([a == b for a, b in zip(true, got)]):.3f} on {len(rows)} segments")
    print(confusion(true, got))
    print("object shape   n   size error without prior median/p90   with prior median/p90")
    for shape in sorted({r[0] for r in rows}) + ["all"]:
        sel = [r for r in rows if shape in ("all", r[0])]
        a, b = np.array([r[3] for r in sel]), np.array([r[4] for r in sel])
        print(f"{shape:12} {len(sel):3}   {np.median(a):8.3f} / {np.percentile(a, 90):.3f}"
              f"                  {np.median(b):8.3f} / {np.percentile(b, 90):.3f}")


def forest_speed(n_segments: int = 20) -> None:
    """What a `kinfu segment` run pays for the classifier: scikit-learn (import, train with the fixed seed,
    one predict_proba per segment) against the packaged numpy Forest (load, same predictions), one process."""
    import time

    with np.load(sp.FEATURES_FILE) as data:
        X = data["X"][:n_segments]
    t0 = time.perf_counter()
    import sklearn.ensemble  # noqa: F401  (the import alone is most of it)

    t1 = time.perf_counter()
    model = sp.train_classifier()
    ref = np.array([model.predict_proba(x[None])[0] for x in X])
    t2 = time.perf_counter()
    forest = sp.load_classifier.__wrapped__()
    ours = np.array([forest.predict_proba(x[None])[0] for x in X])
    t3 = time.perf_counter()
    assert np.array_equal(ours, ref)
    print(f"{n_segments} segments: scikit-learn import {t1 - t0:.3f} s + train and predict {t2 - t1:.3f} s; "
          f"numpy Forest load and predict {t3 - t2:.3f} s; ratio {(t2 - t0) / (t3 - t2):.0f}x, same class shares")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "forest":
        forest_speed()
        sys.exit()
    if len(sys.argv) > 1 and sys.argv[1] == "pipeline":
        pipeline_prior(int(sys.argv[2]) if len(sys.argv) > 2 else 3)
        sys.exit()
    held_out(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
    scenes(int(sys.argv[2]) if len(sys.argv) > 2 else 3)
    for part in (False, True):
        prior_size_error(int(sys.argv[3]) if len(sys.argv) > 3 else 15, part)
