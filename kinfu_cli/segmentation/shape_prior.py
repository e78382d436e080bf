"""Shape prior (Vezzani 2019 thesis, ch. 7.3): classify a segment as box / cylinder / sphere / generic and
bound the superquadric exponents around the class's values (eq. 7.11).

The thesis classifies images with ResNet + SVM; we classify the point cloud with a scikit-learn random
forest on geometric features: the sorted extents and the exponents of a free superquadric fit, its residual,
and statistics of local curvature (surface variation) and of how the normals line up with the fit's axes
(a box's normals cluster on three axes, a cylinder's on one, a sphere's on none).

The package ships the training set's features (`shape_prior_features.npz`, generated primitives with a
fixed seed by `training_set`) and the forest scikit-learn trains on them with a fixed seed, exported as plain
node arrays (`shape_prior_forest.npz`; rebuild both with `python -m kinfu_cli.segmentation.shape_prior`).
`Forest.predict_proba` walks those arrays in numpy: a `kinfu segment` run then neither imports scikit-learn
(0.8 s) nor trains (0.2-0.3 s), the file does not depend on the scikit-learn version the way a pickled
model does, and loading it runs no pickled code. Tests hold it equal to scikit-learn's own predict_proba.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.segmentation.superquadric import E_MAX, E_MIN, SegmentError, SuperquadricFit, fit_superquadric

CLASSES = ("box", "cylinder", "sphere", "generic")
# generated primitive kind -> class ("sphere" is the rounded class of eq. 7.11: e1 = e2 = 1, any semi-axes)
KIND_CLASS = {"box": "box", "cylinder": "cylinder", "sphere": "sphere", "ellipsoid": "sphere",
              "cone": "generic", "capsule": "generic"}
# eq. 7.11: class exponents (e1, e2) in our order (e1 acts on the z axis: a cylinder along z is (0.1, 1.0);
# the thesis writes (lambda4, lambda5) = (1.0, 0.1) in its own axis convention) and the margins
# (Delta_l, Delta_u); the thesis' example uses Delta_l = 0, Delta_u = 0.4 for the box.
PRIOR_EXPONENTS = {"box": (0.1, 0.1), "cylinder": (0.1, 1.0), "sphere": (1.0, 1.0)}
DELTA_LOWER = 0.4
DELTA_UPPER = 0.4
FEATURES_FILE = Path(__file__).with_name("shape_prior_features.npz")
FOREST_FILE = Path(__file__).with_name("shape_prior_forest.npz")
FOREST_PARAMS = {"n_estimators": 150, "min_samples_leaf": 2, "random_state": 0}
MIN_POINTS = 30
FEATURE_NAMES = ("extent_mid_ratio", "extent_min_ratio", "e1", "e2", "residual_ratio", "variation_mean",
                 "variation_std", "variation_p90", "edge_share", "normal_axis_mean", "normal_axis_p10",
                 "normal_z_mean")


def exponent_bounds(shape_class: str) -> tuple[tuple[float, float], tuple[float, float]]:
    """Eq. 7.11: ((lo1, hi1), (lo2, hi2)) = class exponents -/+ (Delta_l, Delta_u), clipped to [0.1, 1.9];
    "generic" gets the default [0.1, 1.9] for both."""
    if shape_class not in CLASSES:
        raise ConfigError(f"expected one of {', '.join(CLASSES)}, got {shape_class!r}", parameter="shape_class")
    if shape_class == "generic":
        return (E_MIN, E_MAX), (E_MIN, E_MAX)
    return tuple((max(E_MIN, e - DELTA_LOWER), min(E_MAX, e + DELTA_UPPER))  # type: ignore[return-value]
                 for e in PRIOR_EXPONENTS[shape_class])


def shape_features(points: np.ndarray, fit: SuperquadricFit | None = None, k: int = 16) -> np.ndarray:
    """The FEATURE_NAMES vector of a segment (N, 3) m; `fit` is its free superquadric fit (made if absent).

    Raises SegmentError for fewer than MIN_POINTS finite points."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise SegmentError(f"shape prior: points must be (N, 3), got shape {pts.shape}")
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < MIN_POINTS:
        raise SegmentError(f"shape prior: the segment has {len(pts)} finite points, need at least "
                           f"{MIN_POINTS} (points)")
    fit = fit if fit is not None else fit_superquadric(pts)
    sq = fit.superquadric
    dims = np.sort(2 * sq.size)[::-1]
    # local PCA on k neighbours: surface variation l0 / (l0 + l1 + l2) and the normal (smallest eigenvector)
    sub = pts if len(pts) <= 1500 else pts[np.random.default_rng(0).choice(len(pts), 1500, replace=False)]
    _, nn = cKDTree(pts).query(sub, k=min(k, len(pts)))
    nb = pts[nn] - pts[nn].mean(axis=1, keepdims=True)
    w, v = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    variation = w[:, 0] / np.maximum(w.sum(axis=1), 1e-18)
    normals_local = np.abs(v[:, :, 0] @ sq.rotation)  # |components| in the superquadric frame
    axis_align = normals_local.max(axis=1)
    return np.array([dims[1] / dims[0], dims[2] / dims[0], sq.exponents[0], sq.exponents[1],
                     fit.residual / dims[0], variation.mean(), variation.std(), np.percentile(variation, 90),
                     float(np.mean(variation > 0.02)), axis_align.mean(), np.percentile(axis_align, 10),
                     normals_local[:, 2].mean()])


def training_set(n_per_kind: int = 60, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Features (M, F) and class indices (M,) of generated primitives: every kind of KIND_CLASS, half full
    surfaces and half partial views, random sizes (3-20 cm) and poses, 1 mm noise."""
    from kinfu_cli.segmentation.shape_samples import primitive_cloud  # generation only, not needed to predict

    rng = np.random.default_rng(seed)
    X, y = [], []
    for kind, cls in KIND_CLASS.items():
        for i in range(int(n_per_kind)):
            pts = primitive_cloud(kind, rng, n=int(rng.integers(400, 1500)), noise=float(rng.uniform(0.0005, 0.002)),
                                  partial=bool(i % 2))
            X.append(shape_features(pts))
            y.append(CLASSES.index(cls))
    return np.asarray(X), np.asarray(y)


def save_training_set(path: Path = FEATURES_FILE, n_per_kind: int = 60, seed: int = 0) -> Path:
    X, y = training_set(n_per_kind, seed)
    np.savez_compressed(path, X=X, y=y, feature_names=np.array(FEATURE_NAMES), classes=np.array(CLASSES),
                        seed=seed, n_per_kind=n_per_kind)
    return path


def train_classifier(path: str | Path = FEATURES_FILE):
    """The scikit-learn random forest trained on the packaged features (fixed seed: the same model every
    time); what `FOREST_FILE` exports."""
    from sklearn.ensemble import RandomForestClassifier

    with np.load(path) as data:
        if tuple(data["feature_names"].tolist()) != FEATURE_NAMES:
            raise ConfigError(f"{path}: features {data['feature_names'].tolist()} do not match this version; "
                              f"rebuild it with save_training_set", parameter="path")
        X, y = data["X"], data["y"]
    return RandomForestClassifier(**FOREST_PARAMS, n_jobs=1).fit(X, y)


@dataclass(frozen=True)
class Forest:
    """A trained tree ensemble as node arrays (all trees concatenated; leaves have left == -1): enough to
    predict as scikit-learn does, without scikit-learn."""

    feature: np.ndarray  # (nodes,) int: the feature a split tests
    threshold: np.ndarray  # (nodes,) float64: go left when x[feature] <= threshold (x as float32, as sklearn)
    left: np.ndarray  # (nodes,) int: global index of the left child, -1 at leaves
    right: np.ndarray  # (nodes,) int
    proba: np.ndarray  # (nodes, classes): class shares of the training samples at the node
    roots: np.ndarray  # (trees,) int

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        """Mean over the trees of the leaf's class shares, (n, classes)."""
        X = np.asarray(X, dtype=np.float32).astype(np.float64)  # sklearn's trees compare float32 features
        rows = np.arange(len(X))[:, None]
        node = np.broadcast_to(self.roots, (len(X), len(self.roots))).copy()
        while True:  # one step down every tree per pass: as many passes as the deepest tree
            inner = self.left[node] >= 0
            if not inner.any():
                break
            go_left = X[rows, self.feature[node]] <= self.threshold[node]
            node = np.where(inner, np.where(go_left, self.left[node], self.right[node]), node)
        return self.proba[node].mean(axis=1)

    def predict(self, X: np.ndarray) -> np.ndarray:
        """Class indices (into CLASSES) of the highest mean share."""
        return np.argmax(self.predict_proba(X), axis=1)


def export_forest(model, path: Path = FOREST_FILE) -> Path:
    """Write a fitted scikit-learn forest's trees as `Forest` node arrays."""
    feats, thrs, lefts, rights, probas, roots = [], [], [], [], [], []
    offset = 0
    for est in model.estimators_:
        t = est.tree_
        inner = t.children_left >= 0
        roots.append(offset)
        feats.append(np.where(inner, t.feature, 0))
        thrs.append(t.threshold)
        lefts.append(np.where(inner, t.children_left + offset, -1))
        rights.append(np.where(inner, t.children_right + offset, -1))
        v = t.value[:, 0, :]
        probas.append(v / v.sum(axis=1, keepdims=True))
        offset += t.node_count
    np.savez_compressed(path, feature=np.concatenate(feats).astype(np.int32), threshold=np.concatenate(thrs),
                        left=np.concatenate(lefts).astype(np.int32), right=np.concatenate(rights).astype(np.int32),
                        proba=np.concatenate(probas), roots=np.array(roots, dtype=np.int32),
                        classes=np.array([CLASSES[int(c)] for c in model.classes_]),
                        feature_names=np.array(FEATURE_NAMES))
    return path


@lru_cache(maxsize=2)
def load_classifier(path: str = str(FOREST_FILE)) -> Forest:
    """The packaged forest (`export_forest` of `train_classifier`)."""
    with np.load(path) as data:
        if tuple(data["feature_names"].tolist()) != FEATURE_NAMES or tuple(data["classes"].tolist()) != CLASSES:
            raise ConfigError(f"{path}: forest features / classes do not match this version; rebuild it with "
                              f"export_forest(train_classifier())", parameter="path")
        return Forest(data["feature"], data["threshold"], data["left"], data["right"], data["proba"],
                      data["roots"])


def classify_shape(points: np.ndarray, fit: SuperquadricFit | None = None) -> tuple[str, dict[str, float]]:
    """The segment's class and the class probabilities."""
    proba = load_classifier().predict_proba(shape_features(points, fit)[None, :])[0]
    return CLASSES[int(np.argmax(proba))], {c: float(p) for c, p in zip(CLASSES, proba)}


def fit_with_prior(points: np.ndarray, **fit_kwargs) -> tuple[SuperquadricFit, str]:
    """Classify from a free fit, then re-fit inside the class's eq. 7.11 exponent bounds ("generic" keeps the
    free fit). Returns the fit and the class. `kinfu segment` uses `segmentation.pipeline._fit_one`, which also
    keeps the free fit when it already lies inside the bounds or fits clearly better."""
    free = fit_superquadric(points, **fit_kwargs)
    cls, _ = classify_shape(points, free)
    if cls == "generic":
        return free, cls
    return fit_superquadric(points, **{**fit_kwargs, "exponent_bounds": exponent_bounds(cls)}), cls


if __name__ == "__main__":  # rebuild the packaged training features and the forest trained on them
    print(save_training_set())
    print(export_forest(train_classifier()))
