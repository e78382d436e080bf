"""Shape prior (thesis 7.3) accuracy: held-out generated primitives (a seed the packaged training set did not
use) and the segments of the synthetic scenes (ground-truth object labels of kinfu_cli.sim scenes: boxes,
cylinders, spheres, cones, tori, mugs); plus the size error of the fit with and without the prior's bounds
on partial views of known primitives.

    PYTHONPATH=$PWD python benchmarks/bench_shape_prior.py [n_per_kind] [n_scenes] [n_size]
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
    """Max relative extent error of the fit, free vs with the prior, on known primitives (random pose)."""
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
            g, cls = sp.fit_with_prior(pts)
            ok += cls == kind
            free.append(np.max(np.abs(np.sort(2 * f.superquadric.size) - truth) / truth))
            prior.append(np.max(np.abs(np.sort(2 * g.superquadric.size) - truth) / truth))
        print(f"{kind:9} {np.median(free):8.3f} / {np.percentile(free, 90):.3f}     "
              f"{np.median(prior):8.3f} / {np.percentile(prior, 90):.3f}        {ok}/{n}")


if __name__ == "__main__":
    held_out(int(sys.argv[1]) if len(sys.argv) > 1 else 20)
    scenes(int(sys.argv[2]) if len(sys.argv) > 2 else 3)
    for part in (False, True):
        prior_size_error(int(sys.argv[3]) if len(sys.argv) > 3 else 15, part)
