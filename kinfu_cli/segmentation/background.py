"""Which segments are background: not standing on the support plane's seen extent.

A grid sized to everything a view observes (kinfu fuse's default, up to its maximum depth) gives a single view
of a tabletop the wall behind it, the floor, the table's front and the furniture beside it too. The thesis segments a
workspace box around the table; here those surfaces became segments like the objects (on our simulated room, a
wall or a cabinet added 1-2 "objects" to each view of 5-11). Not in the thesis: a segment is background when
most of its points (each counted once) lie

- below the support plane, more than `plane_distance` under it (a cabinet or chair beside the table; surfaces
  wholly under the table's height already join the support plane, segments.py step 5), or
- beyond the support plane's extent: outside the convex hull of the support's own points (its largest connected
  part of up-facing points at its height) by more than `background_margin`, where the volume saw that the support
  ends: somewhere between `background_margin` out from the hull edge and the point's foot, the plane level was
  observed empty under the plane (a ray went past the table's edge there). Needs the volume's labels (`space`).

An object on the table stands inside that hull, even where it hides the table behind it (the hull is convex),
and one overhanging an edge keeps most of its points over the table. One whose foot the image border cuts off
(with the table under it) lies outside the hull, but the volume never saw the plane level there: unknown, so it
stays an object. Nothing is background in a room (structure.py: floor and walls found; a table there is
furniture), without a support plane, or when the support spans less than MIN_SUPPORT_SPAN along either axis.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from kinfu_cli.core.grid import EMPTY
from kinfu_cli.core.point_pairs import bounded_pairs, pair_components
from kinfu_cli.core.poses import plane_axes
from kinfu_cli.segmentation.bridges import SpaceQuery
from kinfu_cli.segmentation.segments import PLANE_LABEL, Segmentation, SegmentationParams

MAJORITY = 0.5  # share of a segment's points below or beyond the support for it to be background
MIN_SUPPORT_SPAN = 0.2  # m: a support whose points span less (either way along the plane) decides nothing
BEYOND_SAMPLES = 8  # places between the hull's edge (+ margin) and a point's foot where the plane level is read
TABLE_DEPTH = 3  # voxels under the plane read too: a seen table is occupied there, noise may carve its first voxel

BELOW = "below the support plane"
BEYOND = "beyond the support plane's extent"


def background_segments(seg: Segmentation, params: SegmentationParams, space: SpaceQuery | None = None
                        ) -> dict[int, str]:
    """Segment id -> why it is background (BELOW or BEYOND; BEYOND only with the volume's `space`); empty when
    the rule does not apply (see the module)."""
    if (params.background_margin <= 0 or seg.plane is None
            or (seg.stats.get("structure") or {}).get("room")):
        return {}
    n, d = seg.plane[:3], float(seg.plane[3])
    h = seg.points @ n + d
    # the support's own surface: label 0 also takes object feet and bands of walls at its height (segments.py 5, 7)
    flat = seg.normals @ n >= np.cos(np.radians(params.up_tolerance_deg))
    support = _main_part(seg.points[(seg.labels == PLANE_LABEL) & (np.abs(h) <= 2 * params.plane_distance) & flat],
                         params.adjacency_radius)
    if len(support) < 3:
        return {}
    axes = plane_axes(n)
    sup_uv = support @ axes.T
    if np.any(np.ptp(sup_uv, axis=0) < MIN_SUPPORT_SPAN):
        return {}
    try:
        hull = ConvexHull(sup_uv)
    except (QhullError, ValueError):  # all support points on a line
        return {}
    pos = seg.labels > 0  # the segments' points only: the plane's and the dropped ones decide nothing
    lab = seg.labels[pos]
    below = h[pos] < -params.plane_distance
    outside = _seen_beyond(seg.points[pos] @ axes.T, hull, seg.plane, axes, params.background_margin, space)
    count = np.maximum(np.bincount(lab), 1)
    share_below = np.bincount(lab, weights=below, minlength=len(count)) / count
    share_beyond = np.bincount(lab, weights=outside & ~below, minlength=len(count)) / count
    out: dict[int, str] = {}
    for s in np.flatnonzero(share_below + share_beyond >= MAJORITY):
        out[int(s)] = BELOW if share_below[s] >= share_beyond[s] else BEYOND
    return out


def _seen_beyond(uv: np.ndarray, hull: ConvexHull, plane: np.ndarray, axes: np.ndarray, margin: float,
                 space: SpaceQuery | None) -> np.ndarray:
    """(N,) bool: the point lies over the plane more than `margin` outside the hull, and the volume saw the plane
    level empty somewhere between `margin` out from the hull edge it is beyond and the point's foot (so the support
    ends there, not the view): at one of up to BEYOND_SAMPLES places on that line, both one and TABLE_DEPTH voxels
    under the plane were observed empty (a table seen there is occupied under its surface, one never seen unknown).
    The first place alone missed a cabinet seen past the table's corner, where the table hides the floor."""
    if space is None:
        return np.zeros(len(uv), dtype=bool)
    # qhull's 2-D facet equations have unit normals: a x + b y + c is the signed distance outside each edge
    dist = uv @ hull.equations[:, :2].T + hull.equations[:, 2]
    edge = np.argmax(dist, axis=1)
    far = dist[np.arange(len(uv)), edge] > margin
    out = np.zeros(len(uv), dtype=bool)
    if not np.any(far):
        return out
    i = np.flatnonzero(far)
    labels_at, voxel = space
    n = plane[:3]
    beyond = dist[i, edge[i]]
    back = np.linspace(0.0, 1.0, BEYOND_SAMPLES)[None, :] * (beyond - margin)[:, None]  # from the foot to the edge
    r_uv = uv[i, None, :] - back[..., None] * hull.equations[edge[i], None, :2]
    on_plane = (r_uv @ axes).reshape(-1, 3) - float(plane[3]) * n
    seen = (labels_at(on_plane - voxel * n) == EMPTY) & (labels_at(on_plane - TABLE_DEPTH * voxel * n) == EMPTY)
    out[i] = seen.reshape(len(i), BEYOND_SAMPLES).any(axis=1)
    return out


def _main_part(points: np.ndarray, radius: float) -> np.ndarray:
    """The largest connected part of the support's points (pairs within `radius`): the table top, without the
    strips of other surfaces that happen to lie at its height and face up (a single view's wall band)."""
    if len(points) < 3:
        return points
    pairs = bounded_pairs(points, radius, what="support plane points", hint="a smaller adjacency_radius",
                          parameter="adjacency_radius")
    comp = pair_components(len(points), pairs)
    return points[comp == np.argmax(np.bincount(comp))]
