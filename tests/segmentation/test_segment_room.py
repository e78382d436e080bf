"""Room-scale segmentation: the floor and walls are the room's structure (label 0), the furniture are objects.

The cloud is built here: a 3 x 2.5 m floor and two 2 m walls seen from a corner 1.5 m up, their surface bumpy
with the Kinect's depth noise at the range they are seen from (sigma 2 cm at 3.5 m, as a fused room's far walls
show, with normals that tilt with the bumps), and three boxes (one in the open, one against each wall) seen
closer. The single support plane (1 cm band) left the bumps as hundreds of patches and joined the walls through
them to the boxes that stand against them."""

from __future__ import annotations

import numpy as np

from kinfu_cli.segmentation.segments import PLANE_LABEL, SegmentationParams, segment_cloud

CAMERA = np.array([2.7, 2.2, 1.5])


def _kinect_sigma(r: np.ndarray) -> np.ndarray:
    """Axial depth noise at range r (m), Nguyen et al. 2012 (the simulator's model)."""
    return 0.0012 + 0.0019 * (r - 0.4) ** 2


def _face(origin, u, v, nu: int, nv: int, normal, rng: np.random.Generator, camera: np.ndarray = CAMERA
          ) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle sampled every 1 cm, pushed along its normal by a smooth random field (wavelengths 4-12 cm)
    scaled by the noise at each point's range from `camera`; normals tilted by the field's slope."""
    a, b = np.meshgrid(np.arange(nu) * 0.01, np.arange(nv) * 0.01, indexing="ij")
    a, b = a.ravel(), b.ravel()
    u, v, normal = (np.asarray(x, float) for x in (u, v, normal))
    pts = np.asarray(origin, float) + np.outer(a, u) + np.outer(b, v)
    k = 2 * np.pi / rng.uniform(0.04, 0.12, 16)
    ang = rng.uniform(0, 2 * np.pi, 16)
    kv = np.stack([k * np.cos(ang), k * np.sin(ang)], 1)
    phase = np.outer(a, kv[:, 0]) + np.outer(b, kv[:, 1]) + rng.uniform(0, 2 * np.pi, 16)
    amp = np.sqrt(2 / 16)
    sigma = _kinect_sigma(np.linalg.norm(pts - camera, axis=1))
    field = amp * np.cos(phase).sum(axis=1)
    grad = -amp * np.sin(phase) @ kv  # (N, 2): d field / d(a, b)
    pts = pts + (sigma * field)[:, None] * normal
    nrm = normal - (sigma[:, None] * grad[:, :1]) * u - (sigma[:, None] * grad[:, 1:]) * v
    return pts, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def _box(lo, hi, skip: set[str], rng: np.random.Generator, camera: np.ndarray = CAMERA
         ) -> tuple[np.ndarray, np.ndarray]:
    """The faces of an axis-aligned box the camera sees, but its bottom and those named in skip ('-x', '+y')."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    n = np.round((hi - lo) / 0.01).astype(int)
    e = np.eye(3)
    faces = [("+z", hi[2], 2, 0, 1), ("-x", lo[0], 0, 1, 2), ("+x", hi[0], 0, 1, 2), ("-y", lo[1], 1, 0, 2),
             ("+y", hi[1], 1, 0, 2)]
    out = []
    for name, level, ax, i, j in faces:
        if name in skip:
            continue
        origin = lo.copy()
        origin[ax] = level
        normal = e[ax] * (1 if name[0] == "+" else -1)
        if (camera - origin) @ normal > 0:
            out.append(_face(origin, e[i], e[j], n[i], n[j], normal, rng, camera))
    return np.concatenate([o[0] for o in out]), np.concatenate([o[1] for o in out])


def room_cloud(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, normals, true labels): 0 floor and walls, 1-3 the boxes."""
    rng = np.random.default_rng(seed)
    parts = [_face([0, 0, 0], [1, 0, 0], [0, 1, 0], 300, 250, [0, 0, 1], rng),  # floor
             _face([0, 0, 0], [0, 1, 0], [0, 0, 1], 250, 200, [1, 0, 0], rng),  # wall x = 0
             _face([0, 0, 0], [1, 0, 0], [0, 0, 1], 300, 200, [0, 1, 0], rng)]  # wall y = 0
    labels = [np.zeros(len(p[0]), dtype=np.int64) for p in parts]
    boxes = [([1.4, 1.2, 0.0], [1.9, 1.6, 0.45], set()),  # in the open
             ([0.8, 0.0, 0.0], [1.8, 0.3, 0.8], {"-y"}),  # against the wall y = 0 (a sofa's back)
             ([0.0, 0.9, 0.0], [0.4, 1.5, 1.2], {"-x"})]  # against the wall x = 0 (a shelf)
    for i, (lo, hi, skip) in enumerate(boxes, start=1):
        p = _box(lo, hi, skip, rng)
        parts.append(p)
        labels.append(np.full(len(p[0]), i, dtype=np.int64))
    pts = np.concatenate([p[0] for p in parts])
    nrm = np.concatenate([p[1] for p in parts])
    gt = np.concatenate(labels)
    # a box hides the floor and wall under and behind it
    hidden = np.zeros(len(pts), dtype=bool)
    for lo, hi, _ in boxes:
        hidden |= (gt == 0) & np.all((pts > np.asarray(lo) - 0.005) & (pts < np.asarray(hi) + 0.005), axis=1)
    return pts[~hidden], nrm[~hidden], gt[~hidden]


def _found(labels: np.ndarray, gt: np.ndarray, obj: int) -> bool:
    """One segment holds >= 80 % of the object's points and the object is that segment's majority."""
    seg, cnt = np.unique(labels[gt == obj], return_counts=True)
    best = seg[np.argmax(cnt)]
    if best <= PLANE_LABEL or cnt.max() < 0.8 * cnt.sum():
        return False
    return np.bincount(gt[labels == best]).argmax() == obj


def test_room_structure_is_label_zero_and_furniture_objects():
    pts, nrm, gt = room_cloud()
    seg = segment_cloud(pts, nrm, SegmentationParams(up=(0.0, 0.0, 1.0)))
    lab = seg.labels
    assert np.mean(lab[gt == 0] == PLANE_LABEL) > 0.97
    for obj in (1, 2, 3):
        assert _found(lab, gt, obj), obj
    # hardly any segment beyond the three boxes (the old support plane left 100+ patches of floor and wall)
    sizes = np.bincount(lab[lab > 0])
    assert np.sum(sizes > 0) <= 6
    assert seg.stats["structure"]["room"]
    assert len(seg.stats["structure"]["planes"]) == 3  # the floor and two walls


def test_room_without_structure_over_segments():
    """The same cloud with the search off (the single 1 cm support plane): the bumps of the far floor and walls
    stay as segments of their own (what the structure removes)."""
    pts, nrm, gt = room_cloud()
    lab = segment_cloud(pts, nrm, SegmentationParams(up=(0.0, 0.0, 1.0), structure_planes=0)).labels
    assert np.sum(np.bincount(lab[lab > 0]) > 0) > 20


def test_tabletop_with_floor_is_no_room():
    """A table with boxes and the floor under it (one bounding plane: the table has the floor below it) keeps
    the single-support behaviour: the labels are those of the search turned off."""
    rng = np.random.default_rng(1)
    cam = np.array([0.0, -0.8, 1.4])
    parts = [_face([-1.0, -1.0, 0.0], [1, 0, 0], [0, 1, 0], 200, 200, [0, 0, 1], rng, cam),  # floor
             _face([-0.6, -0.4, 0.7], [1, 0, 0], [0, 1, 0], 120, 80, [0, 0, 1], rng, cam),  # table top
             _box([-0.2, -0.1, 0.7], [0.0, 0.1, 0.85], set(), rng, cam),
             _box([0.2, 0.0, 0.7], [0.3, 0.1, 0.8], set(), rng, cam)]
    pts = np.concatenate([p[0] for p in parts])
    nrm = np.concatenate([p[1] for p in parts])
    on = segment_cloud(pts, nrm, SegmentationParams(up=(0.0, 0.0, 1.0)))
    off = segment_cloud(pts, nrm, SegmentationParams(up=(0.0, 0.0, 1.0), structure_planes=0))
    assert not on.stats["structure"]["room"]
    assert np.array_equal(on.labels, off.labels)
    assert on.plane[3] < -0.69  # the table (z = 0.7) is the support, not the floor


def test_room_y_down_world():
    """The same room in a y-down world (rotated +90 deg about x, up -y, as `kinfu synth --world y-down`): the
    structure does not assume z."""
    pts, nrm, gt = room_cloud()
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # z -> -y
    seg = segment_cloud(pts @ rot.T, nrm @ rot.T, SegmentationParams(up=(0.0, -1.0, 0.0)))
    lab = seg.labels
    assert np.mean(lab[gt == 0] == PLANE_LABEL) > 0.97
    assert all(_found(lab, gt, obj) for obj in (1, 2, 3))
    assert abs(seg.plane[1] + 1.0) < 0.01 and abs(seg.plane[3]) < 0.02  # the floor y = 0 is the support


def test_room_support_entry_describes_the_floor_not_the_whole_room():
    """segments.json's support entry: in a room label 0 is floor and walls, so its box and centroid are taken
    over the floor's points (before: a box spanning the walls' 2 m height); the structure is counted beside."""
    from dataclasses import replace

    from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_cloud

    pts, nrm, _ = room_cloud()
    base = SegmentOptions(superquadrics=False)
    opts = replace(base, segmentation=replace(base.segmentation, up=(0.0, 0.0, 1.0)))
    doc = analyse_cloud(pts, nrm, opts, up_source="option").to_json()
    (support,) = [s for s in doc["segments"] if s["kind"] == "support_plane"]
    assert abs(support["centroid"][2]) < 0.05  # on the floor (z = 0), not halfway up the walls
    assert max(support["oriented_box"]["extents"]) < 3.2 and min(support["oriented_box"]["extents"]) < 0.25
    assert support["structure"]["points"] > 1.5 * support["point_count"] and len(support["structure"]["planes"]) == 3
