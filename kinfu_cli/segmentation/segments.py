"""Segmentation of the surface cloud: support plane, supervoxels, merging across convex boundaries.

Thesis Alg. 4 line 4 uses PCL's VCCS supervoxels + LCCP (Stein et al. 2014). This is the same idea in
numpy/scipy:

0. Room structure (structure.py; not in the thesis): in a room (two room-sized planes at an angle that bound the
   scene: a floor and a wall), the floor, walls and ceiling with a band that follows their own noise are label 0
   with the support; after LCCP, segments within STRUCT_REACH band half-widths of them join it, and the
   furniture's feet are grown back out of the band. A tabletop scene (at most one bounding plane) is left as before.
1. Support plane: RANSAC (open3d's `segment_plane` redone in numpy: plane_ransac.py; up to `max_planes` rounds)
   on points whose normal is within `up_tolerance_deg` of `up`; the highest plane holding >= `min_plane_fraction`
   of the points, or >= `min_up_facing_fraction` of those up-facing points (and at least `min_segment_points`), or
   (outside rooms) one that spans SUPPORT_MIN_SPAN both ways, is the support (the table, not the floor); its inliers
   with a matching normal become segment 0. Without `up` the
   largest plane stands for it (only planes within SUPPORT_PARALLEL_DEG of it compete), and a plane faces the side
   its points' normals point to.
2. Supervoxels (VCCS-like): seeds on a `seed_resolution` grid, then a few k-means rounds where each point
   joins the closest of its 8 spatially nearest seeds under the VCCS distance
   D^2 = w_s |dx|^2 / R_seed^2 + w_n (1 - n_p . n_s) + w_c |c_p - c_s| (the colour term, as PCL's VCCS,
   only when the cloud has colours: RGB in [0, 1], Euclidean); each supervoxel is then split into its
   spatially connected parts (so one never bridges two objects).
3. Adjacency: supervoxels touching within `adjacency_radius`.
4. LCCP: an edge between supervoxels (centroids x1, x2, normals n1, n2, d = (x1 - x2)/|x1 - x2|) is
   convex when (n1 - n2) . d >= 0 and d is not within `sanity_angle_deg` of n1 x n2 (LCCP's sanity
   criterion against singular configurations), or when the normals differ by less than `concavity_tolerance_deg`
   (smooth surfaces); with colours, an edge whose supervoxels' mean colours differ by more than `t_lccp`
   (in `color_distance`, chromaticity by default) is cut (thesis eq. 4.15: LCCP alone ignores colour); segments
   are the connected components.
   method "flood-fill" replaces steps 2-4 by the thesis's baseline (eqs. 4.13-4.14): neighbouring points
   stay joined when w_c d(c1, c2) + w_n (1 - n1 . n2) < `t_ff` (d: `color_distance`).
4b. Concave plane cuts (after CPC, Schoeler et al. 2015; not in the thesis): an LCCP segment still joined across a
   concave crease through some flat or convex path (two touching boxes whose front faces are one plane; a box whose
   top overhangs its base) is cut by the plane of a face at one of its concave point pairs when, of the point pairs
   the plane separates, at least `cut_concave_fraction` are concave (normals bent by more than
   `cut_min_angle_deg`), and the smaller piece holds at least `cut_min_ratio` of the larger (a mug's handle, one
   fifth of the body, is a part, not an object); up to `cut_rounds` rounds, the best of `cut_candidates` sampled
   face planes per segment and round; only segments whose bounding-box diagonal is at most `cut_max_size`. With a
   support plane and step cuts on, a cut must leave one piece off the support (no point within 2 x
   `plane_distance` of it): objects side by side both stand on it and are 4a's; a cut between two standing pieces
   takes a part off an object (a mug's handle with a slice of its body, a box's side). Without 4a, 4b does both.
4a. Step cuts (before 4b; not in the thesis): two touching boxes of different heights whose front and back faces are one
   plane show the concave crease only along the step, too short a share of the seam for 4b. A segment (at most
   `cut_max_size`) whose up-facing points form two levels (heights that many of them share: the TSDF's rounded
   edge leaves a few between the tops) whose medians are at least `step_min_height` apart, with a vertical plane
   (from the normals between the levels, or from the upper top's centre towards the lower's) that has the whole
   lower top in front and the whole upper top behind,
   is cut along that plane (or the step face's own vertical plane at its crease) when both pieces stand on the
   support and the smaller holds >= `cut_min_ratio` of
   the larger (a box on a larger box has the base's top all round it, so no such plane exists). The pieces are
   not cut again in 4b: its best face plane for such a pair can be the lower box's top, which also leaves two
   convex boxes, one of them floating.
5. Segments that stay within 2 x `plane_distance` of the support plane (its edges and sides) join it.
5b. Fragments: a segment under `fragment_points` whose border points lie mostly (>= `fragment_share`) against one
   larger object segment is a piece of it and joins it; a small object on the support borders mostly the plane
   and stays (real fused scenes break box rims and card packs into such pieces).
5c. Floating pieces (not in the thesis): nothing floats, so a segment seen wholly above the support (lowest point
   over FLOAT_HEIGHT) that touches no other segment rests on a part the view hides (a drill's barrel hides the top
   of its handle, leaving a gap in a single view) and joins the segment under it: the one that has a lower point
   within FLOAT_RADIUS across (along the support plane) of most of its points, when those are >= FLOAT_SHARE of
   them. An object behind another is beside it, not over it; one resting on another touches it.
5d. Narrow necks (not in the thesis): an object resting on another stands on a base about as wide as itself (a box
   on a box). A segment off the support whose lowest part touches a standing segment, whose centre lies over it
   (inside the hull of its points along the support plane) and whose contact with it spans less than NECK_RATIO
   of its own horizontal extent (a drill's handle and barrel on its battery: it would topple alone) is a part of
   the standing segment and joins it; an object behind another (its foot hidden) is not over it and stays.
5e. Bridges (bridges.py, only with the volume's labels): two segments of one surface apart by a band of missing
   depth (never-observed voxels, no observed empty one) join; between two objects the gap is observed empty.
6. Segments smaller than `min_segment_points` join their most-connected neighbour (a large one first; fragments
   merge with each other); isolated specks join the support plane when at its level, a segment within
   `adjacency_radius`, or are dropped (label -1).
7. Feet (not in the thesis): with colours, object points within `plane_color_margin` of the support whose colour
   is nearer the plane's join it; then every point under FOOT_BAND within `foot_radius` of an object's side is
   decided on its own by the nearer surface: the object's when it rises over `foot_height` (half a voxel) or its
   normal is bent more than `foot_normal_deg` from up, else the support's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.spatial import ConvexHull, QhullError, cKDTree

from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, VolumeError
from kinfu_cli.core.grid import check_up
from kinfu_cli.core.neighbours import grid_cells
from kinfu_cli.core.point_pairs import MAX_POINT_PAIRS, bounded_pairs, pair_components
from kinfu_cli.core.poses import plane_axes
from kinfu_cli.segmentation.bridges import BridgeParams, join_across_unknown
from kinfu_cli.segmentation.color_distances import (COLOR_DISTANCES, color_distance, color_features,
                                                     feature_distance)
from kinfu_cli.segmentation.group_stats import group_percentile
from kinfu_cli.segmentation.plane_ransac import ransac_plane
from kinfu_cli.segmentation.seed_assignment import assign_to_seeds
from kinfu_cli.segmentation.structure import find_structure

PLANE_LABEL = 0
NOISE_LABEL = -1
METHODS = ("lccp", "flood-fill")
# an object point near the support plane joins it when its colour is this much nearer the plane's mean colour
# than its segment's (tuned on synth seeds 0-3: 1.0 / 0.5 / 0.3 gave boundary P 0.931 / 0.954 / 0.929)
PLANE_COLOR_RATIO = 0.5
CUT_FACE_RADIUS = 0.03  # face-plane cuts: the face's points are counted within this of the candidate point (m)
# step cuts (4a): a top level is a height shared by at least `need` up-facing points within this (m); the TSDF
# rounds a step's edge and leaves a few up-facing points between the two tops, which otherwise fill the gap
# (tuning seeds 0, 1, 8-139, objects scenes, mode, with the gap as the step: 0 / 0.0025 / 0.005 gave object recall
# 0.979 / 0.984 / 0.983)
STEP_LEVEL_BAND = 0.0025
# a plane too small a share of the points for the support rule still qualifies when its inliers span this much both
# ways (5-95 %, m): a table seen with much floor around it (the bundled sample: floor 86 k points, table 11 k, so
# the floor was the support and the table an object); objects' tops are smaller (the generated ones <= 0.3 m)
SUPPORT_MIN_SPAN = 0.4
SUPPORT_SPAN_CELL = 0.02  # ... of one connected patch: cells of this side (m), about three 6 mm voxels
SUPPORT_PARALLEL_DEG = 5.0  # without an up, support candidates are the planes within this of the largest plane's
# normal (a table and the floor are parallel within a degree or two; RANSAC's fit tilts a 1 m table by well under one)
STRUCT_REACH = 2.0  # a segment whose points (95 %) lie within this many band half-widths of the room's structure is
# structure (the bumpy layer off a far wall or floor, beyond its band)
STRUCT_FOOT_ROUNDS = 3  # _structure_foot_refine grows objects into the structure's band this many times
# floating pieces (step 5c): a segment whose lowest point is over FLOAT_HEIGHT above the support and that touches no
# other segment joins the segment under it when >= FLOAT_SHARE of its points have a lower point of it within
# FLOAT_RADIUS across (along the support's plane). Single views, tuning seeds: no floating segment in the objects
# scenes (0, 1, 8-11); drill barrels over their hidden handles (household 0-5) had shares 0.13-0.56
FLOAT_HEIGHT = 0.02
FLOAT_RADIUS = 0.01
FLOAT_SHARE = 0.1
# narrow necks (step 5d): a segment off the support resting on a standing one, over it, joins it when its contact
# with it spans less than NECK_RATIO of its own horizontal extent (contact: its points within CONTACT_BAND of its
# lowest point that touch the standing one). Single views (bench_single_view, up none), tuning seeds only: boxes
# on boxes (objects 0, 1, 8-11) 0.645-1.14, drill handle + barrel on its battery (household 0-5) 0.14-0.49
NECK_RATIO = 0.55
CONTACT_BAND = 0.015
FOOT_BAND = 0.015  # feet (step 7): object points higher than this over the support are the object's side, never a foot (m)


MAX_DISTANCE_M = 10.0  # the largest seed_resolution, adjacency_radius, plane_distance: beyond any scene
MAX_ADJACENCY_PAIRS = MAX_POINT_PAIRS  # the adjacency search's bound (core.point_pairs: its memory, its estimate)


@dataclass
class SegmentationParams:
    """Every knob of the segmentation, with its thesis/PCL meaning (defaults: thesis ch. 4 VCCS values)."""

    seed_resolution: float = 0.04  # VCCS seed spacing (m; thesis ch. 4 used 0.05 on 1 cm voxels)
    spatial_importance: float = 0.1  # alpha_p
    normal_importance: float = 1.0  # alpha_n (thesis ch. 4: 0.5), also in the Flood Fill cost (eq. 4.14)
    color_importance: float = 1.0  # alpha_c (thesis ch. 4: 1.0), RGB in [0, 1]; also in eq. 4.14
    method: str = "lccp"  # "lccp" (supervoxels + LCCP) or "flood-fill" (the thesis's baseline)
    t_lccp: float | None = None  # LCCP colour pruning T_lccp (eq. 4.15, in color_distance); None = no pruning
    # (with RGB, tuned on synth seeds 0-3: pruning at 0.3-0.6 only split objects along shading; >= 0.8 prunes nothing)
    t_ff: float = 0.5  # Flood Fill threshold T_ff (eq. 4.14; tuned on synth seeds 0-3 with RGB)
    # the colour distance of t_lccp and t_ff (COLOR_DISTANCES, see color_distance). "rgb" is the thesis'; "chroma"
    # ignores shading and gain. Objects scenes, tuning seeds 0, 1, 8-19, LCCP, mode filter P / R / object recall:
    # rgb T_lccp 0.2 0.782 / 0.897 / 0.732, chroma T_lccp 0.04 0.886 / 0.956 / 0.929 (README, colour in segmentation);
    # Flood Fill at T_ff 0.5 alike (0.962 / 0.749 both), at 0.2 rgb 0.609 / 0.863, chroma 0.916 / 0.779
    color_distance: str = "chroma"
    plane_color_margin: float = 0.01  # object points this close to the support plane join it when their
    # colour is nearer the plane's than their segment's (m; 0 = off; needs colours)
    # concave plane cuts (module docstring, step 4b; tuned on synth seeds 0, 1, 8-11; None or 0 = off). The share
    # was 0.35 before never-coloured points were filled (surface.fill_uncoloured); re-chosen on the same seeds:
    # 0.3 / 0.35 / 0.4 / 0.45 gave boundary F 0.835 / 0.854 / 0.858 / 0.848, object recall 0.90 / 0.93 / 0.96 / 0.92
    cut_concave_fraction: float | None = 0.4
    cut_min_angle_deg: float = 30.0
    cut_min_ratio: float = 0.4  # tuning seeds 0, 1, 8-19 (object recall mode / mean): 0.4 0.982 / 0.973, 0.45 0.982 /
    # 0.982 (a mug cut with a slice of its body at 0.40), but a box on a box in test_segment's primitive scene is 0.449
    cut_candidates: int = 200
    cut_rounds: int = 3
    # step cuts (step 4a): two tops at least this far apart (m; the largest gap of the up-facing heights until the
    # levels' median heights replaced it, module docstring); 0 = off.
    # Tuning seeds 0, 1, 8-19, object recall mode / mean: off 0.946 / 0.946, 0.005 and 0.01 0.982 / 0.982, 0.015
    # 0.973 / 0.973, 0.02 0.955 / 0.955 (the TSDF rounds a step, so the gap is less than the step). With the levels'
    # medians, tuning seeds 0, 1, 8-139 (mode, mean alike): 0.005 / 0.007 / 0.01 / 0.015 gave 0.996 / 0.996 / 0.994 /
    # 0.981 and the same boundary P (0.950); 0.007 is one voxel of those scenes (6.9 mm): a smaller step is noise
    step_min_height: float = 0.007
    # the cut plane must be a face's: >= this many points of the segment on it (within plane_distance / 2, normals
    # within 20 deg) within CUT_FACE_RADIUS of the candidate point (0 = off). The cuts made on tuning seeds 0, 1,
    # 8-19 had 6-17 such points, a mug cut through its body at a handle point 2; 3 / 4 / 5 / 6 / 8 gave object
    # recall (mode, mean) 0.982 / 0.982, 0.973 / 0.973, 0.982 / 0.982, 0.982 / 0.982, 0.982 / 0.982
    cut_face_points: int = 5
    cut_max_size: float = 0.4  # only segments whose box diagonal is at most this are cut (m): two graspable
    # objects side by side; a large concave thing (a box on its side, a shelf) keeps its inner corners (chosen on
    # rgbd-tabletop-box: its cuts were all in segments of 0.45-0.6 m; the synth merged twins and stacks are 0.3 m)
    kmeans_iterations: int = 3
    adjacency_radius: float = 0.018  # points closer than this connect their supervoxels (m)
    concavity_tolerance_deg: float = 40.0  # LCCP beta_thresh (PCL default 10; fused TSDF normals are noisier;
    # 20 until the colour fill and fragment merge; tuning seeds 0, 1, 8-11, mode and mean: 20 / 25 / 30 / 35 / 40 /
    # 45 / 50 gave boundary F 0.864 / 0.874 / 0.883 / 0.887 / 0.892 / 0.892 / 0.892, object recall 0.958 at 20, 40, 45)
    sanity_angle_deg: float = 60.0  # LCCP sanity criterion threshold (PCL default)
    min_segment_points: int = 50  # smaller segments merge into a neighbour (50 cm2 at the 1 cm cloud;
    # chosen on synth seeds 0, 1, 8-11 (50 = 100 > 20) and rgbd-tabletop-box (object segments 17 -> 11 at 5 mm))
    plane_distance: float = 0.01  # RANSAC inlier distance (m)
    plane_iterations: int = 1000
    # expected support-plane normal (x, y, z); None = any plane; "auto" = the volume's up where the pipeline
    # knows a volume (segmentation.pipeline), z (0, 0, 1) for a bare cloud
    up: tuple[float, float, float] | str | None = "auto"
    up_tolerance_deg: float = 30.0
    min_plane_fraction: float = 0.1  # a support plane must hold this share of the points,
    # or (up given) this share of the points facing up: a scene whose vertical faces outnumber its horizontal
    # ones (a box on its side filling the view) still has its table
    min_up_facing_fraction: float = 0.3
    max_planes: int = 3  # RANSAC rounds; the highest qualifying horizontal plane is the support
    # fragments (step 5b): a segment under fragment_points whose border runs mostly (>= fragment_share of its
    # border points) along one larger object segment joins it; 0 = off
    fragment_points: int = 100
    fragment_share: float = 0.5
    # object feet (step 7): a point under FOOT_BAND within foot_radius of an object's side is the object's when it
    # is higher than foot_height over the support or its normal is bent more than foot_normal_deg from up, else
    # the support's (0 = off). foot_height is about half the fusion voxel (6.9 mm in the objects scenes: the fused
    # table lies within half a voxel of its plane); 45 deg is the bisector of the table and a vertical side.
    # Tuning seeds 0, 1, 8-19 (objects scenes), mode: off P / R 0.901 / 0.897; foot_height 0.003 / 0.004 / 0.005
    # with 45 deg and 0.02 m 0.902-0.903 / 0.913; foot_radius 0.015 / 0.02 / 0.03 0.901 / 0.912, 0.903 / 0.914,
    # 0.886 / 0.912 (0.03 reaches the table beside the next object)
    foot_radius: float = 0.02
    foot_height: float = 0.0035
    foot_normal_deg: float = 45.0
    # room structure (structure.py): RANSAC rounds of the search for bounding planes (floor, walls; 0 = off), the
    # span a plane needs in both directions (m) and its band in robust residual spreads (module docstring, step 0)
    structure_planes: int = 8
    structure_min_extent: float = 1.5
    structure_sigmas: float = 2.0
    # bridges across unknown space (bridges.py; needs the volume's labels, segment_cloud's `space`): segments
    # apart by at most this much across never-observed voxels join (m; 0 = off). 5 cm: the 5-20 px bands of
    # missing depth real views show at 0.8-1.2 m (up to 4 cm); objects and household single views (tuning seeds)
    # unchanged at 0.05, a box face cut by a 6-10 px band at 320x240 is one segment again (tests/segmentation)
    bridge_gap: float = 0.05
    # segments mostly below the support plane or beyond its extent by more than this are background, not objects
    # (background.py; m, 0 = off): the wall, floor and furniture a single view's whole-frustum grid holds
    background_margin: float = 0.05
    seed: int = 0

    def validate(self) -> None:
        """ConfigError naming the first parameter out of its range."""
        check_number(self.up_tolerance_deg, "up_tolerance_deg", 0, 90, unit="deg")
        for name in ("seed_resolution", "adjacency_radius", "plane_distance"):
            check_number(getattr(self, name), name, 1e-4, MAX_DISTANCE_M, unit="m")
        check_number(self.plane_color_margin, "plane_color_margin", 0, 10, unit="m")
        check_number(self.bridge_gap, "bridge_gap", 0, 1, unit="m")
        check_number(self.background_margin, "background_margin", 0, MAX_DISTANCE_M, unit="m")
        for name in ("spatial_importance", "normal_importance", "color_importance"):
            check_number(getattr(self, name), name, 0, 1e6)
        if self.method not in METHODS:
            raise ConfigError(f"expected one of {', '.join(METHODS)}, got {self.method!r}", parameter="method")
        if self.color_distance not in COLOR_DISTANCES:
            raise ConfigError(f"expected one of {', '.join(COLOR_DISTANCES)}, got {self.color_distance!r}",
                              parameter="color_distance")
        if self.t_lccp is not None:
            check_number(self.t_lccp, "t_lccp", 0, 2)  # every distance is below 2 (rgb sqrt(3), chroma sqrt(2))
        check_number(self.t_ff, "t_ff", 0, 1e6, low_open=True)
        if self.cut_concave_fraction is not None:
            check_number(self.cut_concave_fraction, "cut_concave_fraction", 0, 1)
        check_number(self.cut_min_angle_deg, "cut_min_angle_deg", 0, 180, unit="degrees")
        check_number(self.cut_min_ratio, "cut_min_ratio", 0, 1)
        check_number(self.cut_candidates, "cut_candidates", 1, 10_000, integer=True)
        check_number(self.cut_rounds, "cut_rounds", 0, 100, integer=True)
        check_number(self.cut_max_size, "cut_max_size", 0, 100, unit="m")
        check_number(self.cut_face_points, "cut_face_points", 0, 10 ** 6, integer=True)
        check_number(self.step_min_height, "step_min_height", 0, 10, unit="m")
        check_number(self.sanity_angle_deg, "sanity_angle_deg", 0, 180, unit="degrees")
        check_number(self.seed, "seed", 0, 2 ** 32 - 1, integer=True)
        check_number(self.fragment_points, "fragment_points", 0, 10 ** 9, integer=True)
        check_number(self.fragment_share, "fragment_share", 0, 1)
        check_number(self.foot_radius, "foot_radius", 0, 1, unit="m")
        check_number(self.foot_height, "foot_height", 0, 1, unit="m")
        check_number(self.foot_normal_deg, "foot_normal_deg", 0, 90, unit="degrees")
        check_number(self.structure_planes, "structure_planes", 0, 100, integer=True)
        check_number(self.structure_min_extent, "structure_min_extent", 0, 1e6, unit="m")
        check_number(self.structure_sigmas, "structure_sigmas", 0, 100, low_open=True)
        if not 0 <= self.concavity_tolerance_deg < 90:
            raise ConfigError(f"expected 0..90 degrees, got {self.concavity_tolerance_deg}",
                              parameter="concavity_tolerance_deg")
        if self.min_segment_points < 1:
            raise ConfigError(f"must be >= 1, got {self.min_segment_points}", parameter="min_segment_points")
        if isinstance(self.up, str):
            if self.up != "auto":
                raise ConfigError(f"expected x,y,z, 'auto' or None, got {self.up!r}", parameter="up")
        elif self.up is not None:
            check_up(self.up, "up")

    def up_vector(self) -> np.ndarray | None:
        """The expected support-plane normal as a unit vector (z for "auto"), None for any plane."""
        if self.up is None:
            return None
        return np.array([0.0, 0.0, 1.0]) if isinstance(self.up, str) else check_up(self.up, "up")


@dataclass
class Segmentation:
    """labels (N,): 0 = support plane, 1.. = segments, -1 = dropped noise; plane (4,) a, b, c, d with
    a x + b y + c z + d = 0 and (a, b, c) the unit normal towards the objects, or None."""

    points: np.ndarray
    normals: np.ndarray
    labels: np.ndarray
    plane: np.ndarray | None
    supervoxels: np.ndarray  # (N,) supervoxel id, -1 on the plane
    n_supervoxels: int  # 0 for flood fill (no supervoxels)
    stats: dict = field(default_factory=dict)
    colors: np.ndarray | None = None  # (N, 3) RGB in [0, 1] the segmentation used, None without colour


def detect_support_plane(points: np.ndarray, normals: np.ndarray, params: SegmentationParams,
                         info: dict | None = None, span_rule: bool = True) -> tuple[np.ndarray | None, np.ndarray]:
    """(plane (4,) or None, inlier mask (N,)) by RANSAC (`ransac_plane`) on up-facing points. `info`, when
    given, receives what the search saw: points, up (the unit direction used, None for any), candidate_points
    (normal within up_tolerance_deg of up), planes_tried, largest_plane_points (of the planes with an
    up-facing normal), needed_points and, per qualifying plane, why (`qualified`: "share" or "span").
    span_rule: a plane under the share also qualifies by SUPPORT_MIN_SPAN (off in rooms, whose support is
    the floor: a table there is furniture)."""
    n = len(points)
    up = params.up_vector()
    info = {} if info is None else info
    info.update(points=int(n), up=None if up is None else [float(v) for v in up], candidate_points=0,
                planes_tried=0, largest_plane_points=0, needed_points=int(np.ceil(params.min_plane_fraction * n)))
    none = (None, np.zeros(n, dtype=bool))
    if n < 3:
        return none
    cos_tol = np.cos(np.radians(params.up_tolerance_deg))
    cand = np.abs(normals @ up) >= cos_tol if up is not None else np.ones(n, dtype=bool)
    need = params.min_plane_fraction * n
    if up is not None:
        need = min(need, params.min_up_facing_fraction * cand.sum())
    need = max(need, params.min_segment_points, 3)
    least = max(params.min_segment_points, 3)
    info.update(candidate_points=int(cand.sum()), needed_points=int(np.ceil(need)), qualified=[])
    if cand.sum() < (least if span_rule else need):
        return none
    idx = np.flatnonzero(cand)
    rng = np.random.default_rng(int(params.seed))
    found = []  # (plane, inliers) of the planes that qualify
    remaining = idx
    claimed = np.zeros(n, dtype=bool)  # inliers of the planes tried so far
    for _ in range(max(1, int(params.max_planes))):  # several horizontal planes (floor, table): take the highest
        by_share = len(remaining) >= need  # fewer left: a plane through them counts the earlier planes' points
        if not by_share and not (span_rule and len(remaining) >= least):
            break
        model, inl_idx = ransac_plane(points[remaining], float(params.plane_distance), int(params.plane_iterations),
                                      rng)
        plane = np.asarray(model, dtype=np.float64)
        if not np.linalg.norm(plane[:3]) > 0:
            break  # the points left are collinear (a 1-voxel rod): no plane passes through them, nor will
        plane /= np.linalg.norm(plane[:3])
        if up is not None:
            if plane[:3] @ up < 0:
                plane = -plane
        dist = points @ plane[:3] + plane[3]
        inl = (np.abs(dist) <= params.plane_distance) & (np.abs(normals @ plane[:3]) >= cos_tol)
        if up is None and _faces_down(plane, dist, normals, inl, params.plane_distance):
            plane, dist = -plane, -dist
        facing = up is None or abs(plane[:3] @ up) >= cos_tol
        fresh = inl & ~claimed
        claimed |= inl
        why = "share" if by_share and inl.sum() >= need else (
            "span" if span_rule and fresh.sum() >= least
            and _spans(points[fresh], plane[:3], SUPPORT_MIN_SPAN, SUPPORT_SPAN_CELL) else "")
        ok = bool(why) and facing
        info["planes_tried"] += 1
        if facing:
            info["largest_plane_points"] = max(info["largest_plane_points"], int(inl.sum()))
        if ok:
            found.append((plane, inl))
            info["qualified"].append(why)
        remaining = np.setdiff1d(remaining, remaining[np.asarray(inl_idx, dtype=np.int64)], assume_unique=True)
    if not found:
        return none
    # the highest plane along up (a table above the floor). Without an up, the largest plane gives it, and only
    # planes parallel to that one compete: a plane at an angle to it is no support (a wall, or RANSAC's leftovers
    # of the table with the objects' tops, tilted 10-15 deg in generated single views, which would be "higher");
    # with an up, every plane facing it within up_tolerance_deg competes, as before
    ref = up
    if up is None:
        ref = max(found, key=lambda f: int(f[1].sum()))[0][:3]
        found = [f for f in found if abs(f[0][:3] @ ref) >= np.cos(np.radians(SUPPORT_PARALLEL_DEG))]
    return max(found, key=lambda f: float(np.mean(points[f[1]] @ ref)))


def _spans(points: np.ndarray, normal: np.ndarray, span: float, cell: float) -> bool:
    """Whether the largest connected patch of `points` on a plane of unit `normal` (cells of `cell` m touching
    in 8-neighbourhood) extends at least `span` both ways in it (5-95 %). Connected: RANSAC's inliers of a
    plane through several objects' tops at one height span the table without being one surface."""
    uv = points @ plane_axes(normal).T
    if np.any(uv.max(axis=0) - uv.min(axis=0) < span):
        return False
    ij = np.floor((uv - uv.min(axis=0)) / cell).astype(np.int64)
    # the occupied cells only: a dense grid over a coarse volume's extent (6 m voxels: 1e10 cells) ran out of memory
    cells, at = np.unique(ij, axis=0, return_inverse=True)
    width = int(cells[:, 1].max()) + 3  # j + 1 + dj stays in 0..width-1 for dj in -1..1
    key = cells[:, 0] * width + cells[:, 1] + 1  # increasing: np.unique sorts the rows
    edges = []
    for di, dj in ((0, 1), (1, -1), (1, 0), (1, 1)):  # half the 8-neighbourhood: the edges are undirected
        pos = np.minimum(np.searchsorted(key, key + di * width + dj), len(key) - 1)
        hit = key[pos] == key + di * width + dj
        edges.append(np.column_stack([np.flatnonzero(hit), pos[hit]]))
    lab = pair_components(len(cells), np.concatenate(edges))[at.ravel()]
    patch = uv[lab == np.bincount(lab).argmax()]
    lo, hi = np.percentile(patch, [5, 95], axis=0)
    return bool(np.all(hi - lo >= span))


def _faces_down(plane: np.ndarray, dist: np.ndarray, normals: np.ndarray, inl: np.ndarray, margin: float) -> bool:
    """No up given: whether `plane`'s normal points away from the free side, where the objects stand. Surface
    normals point into free space (SurfaceCloud), so the plane's own points say which way it faces; with
    normals that do not agree (a cloud whose normals were not oriented), the side with more points off the
    plane (a table top holds most of a single view's points, so a share of all the points would not do)."""
    side = float(np.mean(normals[inl] @ plane[:3])) if inl.any() else 0.0
    if abs(side) >= 0.5:
        return side < 0
    return int(np.sum(dist < -margin)) > int(np.sum(dist > margin))


def _mean_rows(values: np.ndarray, lab: np.ndarray, k: int) -> np.ndarray:
    """Per-label mean of the rows of `values` (N, D) -> (k, D)."""
    cnt = np.maximum(np.bincount(lab, minlength=k), 1).astype(np.float64)
    return np.stack([np.bincount(lab, values[:, a], minlength=k) for a in range(values.shape[1])], 1) / cnt[:, None]


def _compact(labels: np.ndarray, k: int) -> tuple[np.ndarray, int]:
    """Labels renumbered 0..K'-1 in increasing order of the used ids (np.unique's return_inverse, by bincount)."""
    used = np.bincount(labels, minlength=k) > 0
    remap = np.cumsum(used) - 1
    return remap[labels], int(used.sum())


def supervoxels(points: np.ndarray, normals: np.ndarray, params: SegmentationParams,
                colors: np.ndarray | None = None, pairs: np.ndarray | None = None) -> np.ndarray:
    """VCCS-like supervoxel id per point (N,), spatially connected, ids 0..K-1. With colours (RGB in [0, 1])
    the distance gains PCL's colour term color_importance * |c_p - c_s| (Euclidean in RGB). pairs: the point
    pairs closer than adjacency_radius when the caller has them (found here otherwise)."""
    n = len(points)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    R = float(params.seed_resolution)
    first, inv = grid_cells(points, R)
    # seeds: the centroid of each cell (position, normal, colour)
    k = len(first)
    seed_pos = _mean_rows(points, inv, k)
    seed_nrm = _mean_rows(normals, inv, k)
    seed_nrm /= np.maximum(np.linalg.norm(seed_nrm, axis=1, keepdims=True), 1e-12)
    wc = float(params.color_importance) if colors is not None else 0.0
    seed_col = _mean_rows(colors, inv, k) if wc > 0 else None
    labels = inv
    ws = params.spatial_importance / R ** 2
    wn = params.normal_importance
    for _ in range(max(0, int(params.kmeans_iterations))):
        kk = min(8, len(seed_pos))
        _, cand = cKDTree(seed_pos).query(points, k=kk, workers=-1)
        near = assign_to_seeds(points, normals, cand.reshape(n, kk), seed_pos, seed_nrm, ws, wn, colors, seed_col, wc)
        labels, k = _compact(near, k)
        seed_pos = _mean_rows(points, labels, k)
        seed_nrm = _mean_rows(normals, labels, k)
        seed_nrm /= np.maximum(np.linalg.norm(seed_nrm, axis=1, keepdims=True), 1e-12)
        if seed_col is not None:
            seed_col = _mean_rows(colors, labels, k)
    # split into spatially connected parts
    if pairs is None:
        pairs = adjacency_pairs(points, params.adjacency_radius)
    return pair_components(n, pairs[labels[pairs[:, 0]] == labels[pairs[:, 1]]])


def adjacency_pairs(points: np.ndarray, radius: float) -> np.ndarray:
    """The point pairs (E, 2) closer than `radius` (adjacency_radius). ConfigError first when they would be more
    than MAX_ADJACENCY_PAIRS (core.point_pairs): a radius spanning the cloud makes N^2 / 2 pairs and the search
    runs out of memory instead of answering."""
    return bounded_pairs(points, radius, what="surface points", parameter="adjacency_radius",
                         hint=f"expected a radius near the points' spacing "
                              f"(default {SegmentationParams.adjacency_radius:g} m)")


def _segment_stats(points: np.ndarray, normals: np.ndarray, lab: np.ndarray, k: int):
    cnt = np.bincount(lab, minlength=k).astype(np.float64)
    cen = _mean_rows(points, lab, k)
    nrm = _mean_rows(normals, lab, k)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    return cnt, cen, nrm


def lccp_segments(points: np.ndarray, normals: np.ndarray, pairs: np.ndarray, params: SegmentationParams,
                  colors: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """(segment per point, supervoxel per point, stats): supervoxels joined over convex or smooth edges
    (module docstring, step 4); with colours, an edge whose supervoxels' mean colours differ by more than
    t_lccp (in params.color_distance; thesis eq. 4.15: RGB) is cut whatever its shape. pairs: point pairs closer
    than adjacency_radius."""
    sv = supervoxels(points, normals, params, colors, pairs)
    k = int(sv.max()) + 1
    _, cen, snrm = _segment_stats(points, normals, sv, k)
    a, b = sv[pairs[:, 0]], sv[pairs[:, 1]]
    diff = a != b
    lo, hi = np.minimum(a[diff], b[diff]), np.maximum(a[diff], b[diff])
    key = np.unique(lo * np.int64(k) + hi)  # the sorted unique (lo, hi) rows, as np.unique(axis=0) orders them
    edges = np.stack([key // k, key % k], 1).reshape(-1, 2)
    d = cen[edges[:, 0]] - cen[edges[:, 1]]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    n1, n2 = snrm[edges[:, 0]], snrm[edges[:, 1]]
    convex = np.einsum("ij,ij->i", n1 - n2, d) >= 0
    # LCCP sanity criterion: a convex-looking step whose offset d runs along n1 x n2 is a singular
    # configuration (e.g. two side faces one above the other), not a real convex edge
    s = np.cross(n1, n2)
    sn = np.linalg.norm(s, axis=1)
    singular = np.abs(np.einsum("ij,ij->i", s, d)) > np.cos(np.radians(params.sanity_angle_deg)) * sn
    convex &= ~singular
    smooth = np.einsum("ij,ij->i", n1, n2) >= np.cos(np.radians(params.concavity_tolerance_deg))
    join = convex | smooth
    pruned = 0
    if colors is not None and params.t_lccp is not None:
        f = color_features(_mean_rows(colors, sv, k), params.color_distance)
        far = feature_distance(f[edges[:, 0]], f[edges[:, 1]], params.color_distance) > params.t_lccp
        pruned = int(np.sum(join & far))
        join &= ~far
    keep = edges[join]
    stats = {"supervoxels": k, "adjacent_pairs": int(len(edges)), "convex_pairs": int(len(keep)),
             "color_pruned_pairs": pruned}
    return pair_components(k, keep)[sv], sv, stats


def flood_fill_segments(normals: np.ndarray, pairs: np.ndarray, params: SegmentationParams,
                        colors: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """(segment per point, stats): the thesis's Flood Fill baseline (eqs. 4.13-4.14): neighbouring points
    (closer than adjacency_radius) stay joined when color_importance d(c1, c2) + normal_importance
    (1 - n1 . n2) < t_ff (d: params.color_distance); segments are the connected components. Without colours the
    colour term is 0."""
    cost = params.normal_importance * (1.0 - np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]))
    if colors is not None:
        f = color_features(colors, params.color_distance)  # once per point, not per pair end
        cost += params.color_importance * feature_distance(f[pairs[:, 0]], f[pairs[:, 1]], params.color_distance)
    keep = pairs[cost < params.t_ff]
    return pair_components(len(normals), keep), {"adjacent_pairs": int(len(pairs)), "joined_pairs": int(len(keep))}


def _concave_pairs(points: np.ndarray, normals: np.ndarray, pairs: np.ndarray, min_angle_deg: float) -> np.ndarray:
    """Point pairs across a concave crease: LCCP's convexity test fails and the normals differ by > min_angle_deg."""
    d = points[pairs[:, 0]] - points[pairs[:, 1]]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    n1, n2 = normals[pairs[:, 0]], normals[pairs[:, 1]]
    convex = np.einsum("ij,ij->i", n1 - n2, d) >= 0
    return ~convex & (np.einsum("ij,ij->i", n1, n2) < np.cos(np.radians(min_angle_deg)))


def _best_face_cut(points: np.ndarray, normals: np.ndarray, idx: np.ndarray, seg_pairs: np.ndarray,
                   concave: np.ndarray, params: SegmentationParams, rng: np.random.Generator, chunk: int = 64,
                   planes: np.ndarray | None = None, grounded: np.ndarray | None = None,
                   plane_normals: np.ndarray | None = None) -> tuple[float, np.ndarray | None]:
    """(concave share of the separated pairs, mask over idx of the + side) of the best face plane among
    `cut_candidates` concave pairs of one segment (points idx, its pairs seg_pairs), or (0, None). The planes
    are scored `chunk` at a time as (points x planes) side matrices; ties go to the first plane sampled.
    grounded (mask over all points, or None): only planes that leave one side with no grounded point count
    (the piece cut off rests on the other, it does not stand beside it). plane_normals (len(planes), 3): the
    given planes' normals instead of their points' normals."""
    cand = seg_pairs[concave]
    tol = params.plane_distance / 2  # the face's own points, within noise of its plane, stay on its side
    if planes is None:  # else: the given points' planes
        planes = cand[rng.choice(len(cand), size=min(params.cut_candidates, len(cand)), replace=False)].ravel()
    # the pairs' ends as positions in idx (both ends are in the segment), without an array over the whole cloud
    srt = None if np.all(idx[1:] > idx[:-1]) else np.argsort(idx)
    pa, pb = (np.searchsorted(idx, seg_pairs[:, c], sorter=srt) for c in (0, 1))
    if srt is not None:
        pa, pb = srt[pa], srt[pb]
    x = points[idx]
    n_seg = len(idx)
    g = None if grounded is None else grounded[idx]
    best_share, best_side = 0.0, None
    for c0 in range(0, len(planes), chunk):
        p = planes[c0:c0 + chunk]
        pn = normals[p] if plane_normals is None else plane_normals[c0:c0 + chunk]
        dist = x @ pn.T - np.einsum("ij,ij->i", points[p], pn)  # (points, planes) signed
        plus = dist > tol
        n_plus = plus.sum(axis=0)
        small = np.minimum(n_plus, n_seg - n_plus)
        large = np.maximum(n_plus, n_seg - n_plus)
        ok = small >= np.maximum(params.min_segment_points, params.cut_min_ratio * large)
        if g is not None and g.any():
            n_g = (plus & g[:, None]).sum(axis=0)
            ok &= (n_g == 0) | (n_g == g.sum())
        if params.cut_face_points > 0 and ok.any():  # the plane must be a face's: points on it near the candidate
            sq = (x * x).sum(axis=1)[:, None] - 2 * x @ points[p].T + (points[p] * points[p]).sum(axis=1)
            on = (sq <= CUT_FACE_RADIUS ** 2) & (np.abs(dist) <= tol)
            on &= normals[idx] @ pn.T >= np.cos(np.radians(20.0))
            ok &= on.sum(axis=0) >= params.cut_face_points
        if not ok.any():
            continue
        plus = plus[:, ok]
        cross = plus[pa] != plus[pb]
        n_cross = cross.sum(axis=0)
        share = np.where(n_cross > 0, (cross & concave[:, None]).sum(axis=0) / np.maximum(n_cross, 1), 0.0)
        j = int(np.argmax(share))
        if share[j] > best_share:
            best_share, best_side = float(share[j]), plus[:, j]
    if best_side is None:
        return 0.0, None
    return best_share, best_side


def concave_plane_cuts(points: np.ndarray, normals: np.ndarray, seg: np.ndarray, pairs: np.ndarray,
                       params: SegmentationParams, skip: np.ndarray | None = None,
                       grounded: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """(segments after the concave plane cuts, number of cuts): module docstring, step 4b. seg: segment per
    point (>= 0); pairs: point pairs closer than adjacency_radius; skip: points whose segments are not cut (the
    step cuts' pieces); grounded: points at the support (within 2 plane_distance of it), or None: with it, a cut
    must leave one piece off the support (`_best_face_cut`). The pieces are re-split into connected parts.
    Points and pairs are grouped by segment once per round (a cut only relabels its own segment's points)."""
    if not params.cut_concave_fraction or params.cut_rounds == 0 or len(pairs) == 0:  # None or 0: off
        return seg, 0
    rng = np.random.default_rng(params.seed)
    concave = _concave_pairs(points, normals, pairs, params.cut_min_angle_deg)
    seg = seg.copy()
    cuts = 0
    for _ in range(params.cut_rounds):
        a = seg[pairs[:, 0]]
        same = a == seg[pairs[:, 1]]
        hit = np.unique(a[same & concave])
        if len(hit) == 0:
            break
        k = int(seg.max()) + 1
        n_conc = np.bincount(a[same & concave], minlength=k)
        ext = np.stack([np.full((k, 3), np.inf), np.full((k, 3), -np.inf)])
        np.minimum.at(ext[0], seg, points)
        np.maximum.at(ext[1], seg, points)
        diag = np.linalg.norm(ext[1] - ext[0], axis=1)
        p_order = np.argsort(seg, kind="stable")
        p_start = np.searchsorted(seg[p_order], np.arange(k + 1))
        in_pairs = np.flatnonzero(same)
        e_order = in_pairs[np.argsort(a[in_pairs], kind="stable")]
        e_start = np.searchsorted(a[e_order], np.arange(k + 1))
        before = cuts
        for s in hit:
            if n_conc[s] < 3 or diag[s] > params.cut_max_size or (skip is not None and skip[p_order[p_start[s]]]):
                continue
            idx = p_order[p_start[s]:p_start[s + 1]]
            e = e_order[e_start[s]:e_start[s + 1]]
            share, plus = _best_face_cut(points, normals, idx, pairs[e], concave[e], params, rng, grounded=grounded)
            if plus is not None and share >= params.cut_concave_fraction:
                seg[idx[plus]] = seg.max() + 1
                cuts += 1
        if cuts == before:
            break
    keep = seg[pairs[:, 0]] == seg[pairs[:, 1]]
    return pair_components(len(points), pairs[keep]), cuts


def _step_plane(x: np.ndarray, nx: np.ndarray, h: np.ndarray, up: np.ndarray, params: SegmentationParams
                ) -> tuple[np.ndarray, np.ndarray] | None:
    """(origin, normal) of the step face between two tops of one segment (points x, normals nx, heights over the
    support h), or None: the segment's up-facing points, off the support, fall into two levels (split at the largest
    gap between heights that at least `need` of them share within STEP_LEVEL_BAND) whose medians are at least
    `step_min_height` apart, and a vertical face rising from the lower level has
    the whole lower top in front of it and the whole upper top behind it (two boxes of different heights side by
    side; a box on another has its base's top around it, so no face plane parts the two tops)."""
    cos = np.cos(np.radians(20.0))
    tol = params.plane_distance / 2
    top = np.flatnonzero((nx @ up >= cos) & (h > 2 * params.plane_distance))
    need = max(5, params.min_segment_points // 5)
    if len(top) < 2 * need:
        return None
    order = top[np.argsort(h[top], kind="stable")]
    if STEP_LEVEL_BAND > 0:  # levels only: the rounded edge's few up-facing points between the tops are left out
        hs = h[order]
        count = np.searchsorted(hs, hs + STEP_LEVEL_BAND, "right") - np.searchsorted(hs, hs - STEP_LEVEL_BAND, "left")
        order = order[count >= need]
        if len(order) < 2 * need:
            return None
    gaps = np.diff(h[order])
    gaps[:need - 1] = 0
    gaps[len(gaps) - need + 1:] = 0
    g = int(np.argmax(gaps))
    low, high = order[:g + 1], order[g + 1:]
    h_low, h_high = float(np.median(h[low])), float(np.median(h[high]))
    # the step is the levels' distance: the TSDF rounds the edge, which narrows the gap between them, not that
    # (tuning seeds 0, 1, 8-139, mode, object recall: the gap as the step 0.991 at 1 cm, 0.994 at 7 mm; this 0.994, 0.996)
    if gaps[g] <= STEP_LEVEL_BAND or h_high - h_low < params.step_min_height:
        return None
    # candidate step directions: the horizontal part of the normals between the two levels (the step face, bent by
    # the TSDF at its crease and edge; a step of one or two voxels shows few), and the horizontal direction from the
    # upper top's centre to the lower's; the one parting the two tops with the widest margin wins
    side = np.flatnonzero((nx @ up < cos) & (h > h_low + tol) & (h < h_high - tol))
    n = nx[side] - np.outer(nx[side] @ up, up)
    norm = np.linalg.norm(n, axis=1)
    n = n[norm >= 0.3] / norm[norm >= 0.3, None]
    if len(n) < need:
        n = n[:0]
    c = x[low].mean(axis=0) - x[high].mean(axis=0)
    c -= (c @ up) * up
    if np.linalg.norm(c) > 1e-9:
        n = np.vstack([n, c / np.linalg.norm(c)])
    if len(n) == 0:
        return None
    lo = np.percentile(x[low] @ n.T, 5, axis=0)  # the lower top lies in front of the step face
    hi = np.percentile(x[high] @ n.T, 95, axis=0)  # the upper top behind it
    j = int(np.argmax(lo - hi))
    if lo[j] - hi[j] < -tol:
        return None
    return n[j] * (lo[j] + hi[j]) / 2, n[j]


def step_cuts(points: np.ndarray, normals: np.ndarray, seg: np.ndarray, pairs: np.ndarray, plane: np.ndarray,
              params: SegmentationParams) -> tuple[np.ndarray, int, np.ndarray]:
    """(segments, cuts, mask of the points of the segments cut): module docstring, step 4a. A segment of at most
    `cut_max_size` whose top has two levels parted by a vertical step (`_step_plane`) is cut along the step face's
    plane (the best face-plane cut among its concave points facing along the step, else the plane midway between
    the tops) when both pieces stand on the support and the smaller holds >= `cut_min_ratio` of the larger."""
    stepped = np.zeros(len(seg), dtype=bool)
    if not params.step_min_height or not (seg >= 0).any():
        return seg, 0, stepped
    up = plane[:3]
    h = points @ up + plane[3]
    seg = seg.copy()
    cuts = 0
    grounded = h < 2 * params.plane_distance
    k = int(seg.max()) + 1
    valid = np.flatnonzero(seg >= 0)
    order = valid[np.argsort(seg[valid], kind="stable")]  # points grouped by segment, once
    start = np.searchsorted(seg[order], np.arange(k + 1))
    ext = np.stack([np.full((k, 3), np.inf), np.full((k, 3), -np.inf)])
    np.minimum.at(ext[0], seg[valid], points[valid])
    np.maximum.at(ext[1], seg[valid], points[valid])
    small_enough = np.linalg.norm(ext[1] - ext[0], axis=1) <= params.cut_max_size
    for s in np.flatnonzero(small_enough & (np.diff(start) >= 2 * params.min_segment_points)):
        idx = order[start[s]:start[s + 1]]
        x = points[idx]
        found = _step_plane(x, normals[idx], h[idx], up, params)
        if found is None:
            continue
        plus = (x - found[0]) @ found[1] > params.plane_distance / 2
        # the step face's own plane where its crease shows it: the face-plane cut (4b) over the concave points
        # facing along the step within 1.5 plane_distance of the plane between the tops (the TSDF rounds the step)
        inside = seg == s
        e = np.flatnonzero(inside[pairs[:, 0]] & inside[pairs[:, 1]])
        conc = _concave_pairs(points, normals, pairs[e], params.cut_min_angle_deg)
        ends = np.unique(pairs[e][conc].ravel())
        near = ends[(np.abs(normals[ends] @ found[1]) >= np.cos(np.radians(25.0)))
                    & (np.abs((points[ends] - found[0]) @ found[1]) <= 1.5 * params.plane_distance)]
        if len(near):
            # the face stands on the support, so its plane is vertical: the crease's normals, bent up by the TSDF,
            # lose their vertical part (else the plane tilts through the lower box, a 20 deg tilt 3 cm at its foot)
            hz = normals[near] - np.outer(normals[near] @ up, up)
            hz /= np.maximum(np.linalg.norm(hz, axis=1, keepdims=True), 1e-12)
            _, side = _best_face_cut(points, normals, idx, pairs[e], conc, params, np.random.default_rng(params.seed),
                                     planes=near, plane_normals=hz)
            if side is not None:
                plus = side
        n_plus = int(plus.sum())
        small, large = min(n_plus, len(idx) - n_plus), max(n_plus, len(idx) - n_plus)
        if small < max(params.min_segment_points, params.cut_min_ratio * large):
            continue
        if not (grounded[idx][plus].any() and grounded[idx][~plus].any()):
            continue
        seg[idx[plus]] = seg.max() + 1
        stepped[idx] = True
        cuts += 1
    if cuts:
        keep = seg[pairs[:, 0]] == seg[pairs[:, 1]]
        comp = pair_components(len(points), pairs[keep])
        seg = np.where(seg >= 0, comp, -1)
    return seg, cuts, stepped


def _absorb_small(seg: np.ndarray, pairs: np.ndarray, min_points: int) -> np.ndarray:
    """Segments smaller than min_points join the large segment they share most point pairs with. Fragments that
    touch no large segment merge with the fragments they touch, and the merged piece is kept when it reaches
    min_points (a thin object cut into slivers), else dropped (-1); it never joins a large segment in a second
    round, which would carry table-edge specks into a neighbouring object."""
    seg = seg.copy()
    nseg = int(seg.max()) + 1 if (seg >= 0).any() else 0
    sizes = np.bincount(seg[seg >= 0], minlength=nseg)
    small = (sizes > 0) & (sizes < min_points)
    if not small.any():
        return seg
    sa, sb = seg[pairs[:, 0]], seg[pairs[:, 1]]
    m = (sa != sb) & (sa >= 0) & (sb >= 0)
    c = coo_matrix((np.ones(2 * m.sum()), (np.r_[sa[m], sb[m]], np.r_[sb[m], sa[m]])),
                   shape=(nseg, nseg)).tocsr().tocoo()  # duplicates summed: point pairs per segment pair
    to_large = small[c.row] & ~small[c.col]
    row, col, w = c.row[to_large], c.col[to_large], c.data[to_large]
    order = np.lexsort((-w, row))
    first = order[np.r_[True, row[order][1:] != row[order][:-1]]] if len(order) else order
    target = np.arange(nseg)
    target[row[first]] = col[first]
    lonely = small & (target == np.arange(nseg))  # touching no large segment
    both = lonely[c.row] & lonely[c.col]
    comp = pair_components(nseg, np.stack([c.row[both], c.col[both]], 1))
    rep = np.full(int(comp.max()) + 1, nseg)
    np.minimum.at(rep, comp, np.arange(nseg))  # a merged piece keeps its smallest member's id
    target = np.where(lonely, rep[comp], target)
    seg = np.where(seg >= 0, target[np.maximum(seg, 0)], -1)
    sizes = np.bincount(seg[seg >= 0], minlength=nseg)
    return np.where((seg >= 0) & (sizes[np.maximum(seg, 0)] >= min_points), seg, -1)


def _near(points: np.ndarray, others: np.ndarray, radius: float) -> np.ndarray:
    """Mask of `points` with a point of `others` within radius."""
    if len(others) == 0 or len(points) == 0:
        return np.zeros(len(points), dtype=bool)
    d, _ = cKDTree(others).query(points, distance_upper_bound=radius)
    return np.isfinite(d)


def _merge_fragments(seg: np.ndarray, pairs: np.ndarray, near_plane: np.ndarray, max_points: int, share: float
                     ) -> tuple[np.ndarray, int]:
    """(segments, merges): a segment under max_points whose border lies mostly (>= share of its border points)
    against one larger object segment is a piece of it and joins it; a small object standing on the support
    borders mostly the support (near_plane: points with a support-plane point within adjacency_radius) and
    stays. One pass, smallest fragments first (a fragment joins its neighbour's final segment)."""
    n_seg = int(seg.max()) + 1 if (seg >= 0).any() else 0
    if n_seg < 2:
        return seg, 0
    sizes = np.bincount(seg[seg >= 0], minlength=n_seg)
    sa, sb = seg[pairs[:, 0]], seg[pairs[:, 1]]
    m = (sa != sb) & (sa >= 0) & (sb >= 0)
    # border points of each segment that touch segment t: unique (point, other segment) pairs
    pt = np.r_[pairs[m, 0], pairs[m, 1]]
    other = np.r_[sb[m], sa[m]]
    key = np.unique(pt * np.int64(n_seg) + other)
    pt, other = key // n_seg, key % n_seg
    own = seg[pt]
    border = np.zeros(len(seg), dtype=bool)
    border[pt] = True
    border |= near_plane & (seg >= 0)
    n_border = np.bincount(seg[border & (seg >= 0)], minlength=n_seg)
    touch = coo_matrix((np.ones(len(pt)), (own, other)), shape=(n_seg, n_seg)).tocsr()
    target = np.arange(n_seg)
    merges = 0
    for s in np.argsort(sizes, kind="stable"):
        if sizes[s] == 0 or sizes[s] >= max_points or n_border[s] == 0:
            continue
        row = touch.getrow(s)
        if row.nnz == 0:
            continue
        cand = row.indices[sizes[row.indices] > sizes[s]]
        if len(cand) == 0:
            continue
        w = np.asarray(row[:, cand].todense()).ravel()
        t = cand[int(np.argmax(w))]
        if w.max() >= share * n_border[s]:
            target[s] = t
            merges += 1
    for _ in range(n_seg):  # follow chains (a fragment joined a fragment that joined a segment)
        nxt = target[target]
        if np.array_equal(nxt, target):
            break
        target = nxt
    return np.where(seg >= 0, target[np.maximum(seg, 0)], -1), merges


def _lowest(seg: np.ndarray, h: np.ndarray) -> tuple[int, np.ndarray]:
    """(segment count, lowest height over the support of each segment 0..count-1; inf for an empty id)."""
    valid = seg >= 0
    n_seg = int(seg.max()) + 1 if valid.any() else 0
    low = np.full(n_seg, np.inf)
    np.minimum.at(low, seg[valid], h[valid])
    return n_seg, low


def _join_floating(seg: np.ndarray, points: np.ndarray, pairs: np.ndarray, h: np.ndarray, up: np.ndarray
                   ) -> tuple[np.ndarray, int]:
    """(segments, joins): step 5c. Nothing floats: a segment seen wholly above the
    support (lowest point over FLOAT_HEIGHT) that touches no other segment rests on a part the view does not
    show (a drill's barrel hides the top of its handle; a single view has a gap there), so it joins the segment
    under it: the one below most of its points (a lower point of it within FLOAT_RADIUS along the support plane),
    when they are at least FLOAT_SHARE of its points. An object behind another is not over it, and one resting on
    another touches it (a crease, not a gap), so neither joins."""
    valid = seg >= 0
    n_seg, low = _lowest(seg, h)
    if n_seg < 2:
        return seg, 0
    sa, sb = seg[pairs[:, 0]], seg[pairs[:, 1]]
    m = (sa != sb) & (sa >= 0) & (sb >= 0)
    touching = np.zeros(n_seg, dtype=bool)
    touching[sa[m]] = True
    touching[sb[m]] = True
    floating = np.flatnonzero(np.isfinite(low) & (low > FLOAT_HEIGHT) & ~touching)
    if len(floating) == 0:
        return seg, 0
    flat = points - np.outer(h, up)  # the points' feet on the support plane
    others = np.flatnonzero(valid)
    tree = cKDTree(flat[others])
    target = np.arange(n_seg)
    joins = 0
    for s in floating:
        idx = np.flatnonzero(seg == s)
        d = cKDTree(flat[idx]).sparse_distance_matrix(tree, FLOAT_RADIUS, output_type="ndarray")
        i, j = d["i"], others[d["j"]]
        below = (seg[j] != s) & (h[j] < h[idx[i]])
        key = np.unique(i[below] * np.int64(n_seg) + seg[j[below]])  # (point of s, segment under it)
        if len(key) == 0:
            continue
        cnt = np.bincount(key % n_seg, minlength=n_seg)
        t = int(np.argmax(cnt))
        if cnt[t] >= FLOAT_SHARE * len(idx):
            target[s] = t
            joins += 1
    for _ in range(n_seg):
        nxt = target[target]
        if np.array_equal(nxt, target):
            break
        target = nxt
    return np.where(valid, target[np.maximum(seg, 0)], -1), joins


def _extent(flat: np.ndarray) -> float:
    """Largest distance between two of the points (m); every k-th point of a large set (at most 400)."""
    if len(flat) < 2:
        return 0.0
    flat = flat[::max(1, len(flat) // 400)]
    return float(np.sqrt(((flat[:, None, :] - flat[None, :, :]) ** 2).sum(-1).max()))


def _over(point: np.ndarray, flat: np.ndarray, up: np.ndarray) -> bool:
    """Whether the foot `point` lies inside the convex hull of the feet `flat` (all on the support plane)."""
    axes = plane_axes(up)
    uv = flat @ axes.T
    if len(uv) < 3:
        return False
    try:
        hull = ConvexHull(uv)
    except QhullError:  # fewer than 3 points or all on a line
        return False
    return bool(np.all(hull.equations[:, :2] @ (axes @ point) + hull.equations[:, 2] <= 0))


def _join_necks(seg: np.ndarray, points: np.ndarray, pairs: np.ndarray, h: np.ndarray, up: np.ndarray,
                params: SegmentationParams) -> tuple[np.ndarray, int]:
    """(segments, joins): step 5d. An object resting on another stands on a base about as wide as itself (a box on
    a box, a mug on a book). A piece off the support whose lowest part touches a standing segment, whose centre
    lies over that segment, and which spreads far beyond its narrow contact with it (a drill's handle and barrel
    on its battery) would topple if it were separate: it is a part of the standing segment and joins it. A
    segment whose centre is not over the standing one (an object behind another, its foot hidden) stays."""
    valid = seg >= 0
    n_seg, low = _lowest(seg, h)
    if n_seg < 2:
        return seg, 0
    grounded = low < 2 * params.plane_distance
    sa, sb = seg[pairs[:, 0]], seg[pairs[:, 1]]
    m = (sa != sb) & (sa >= 0) & (sb >= 0)
    pa, pb, sa, sb = pairs[m, 0], pairs[m, 1], sa[m], sb[m]
    flat = points - np.outer(h, up)
    target = np.arange(n_seg)
    joins = 0
    for b in np.flatnonzero(np.isfinite(low) & ~grounded):
        mine = np.r_[pa[sb == b], pb[sa == b]]  # the points of other segments touching b, and which
        other = np.r_[sa[sb == b], sb[sa == b]]
        ok = grounded[other] & (h[mine] <= low[b] + CONTACT_BAND)
        if not ok.any():
            continue
        a = int(np.bincount(other[ok]).argmax())
        # the contact: a's points next to b up to CONTACT_BAND above b's lowest point, or above the lowest of them
        # when b hangs lower elsewhere (a box on a box, cut from it by colour along a seam below its edge, kept two
        # points of its contact and joined it)
        touch = other == a
        floor = max(low[b], h[mine[touch]].min())
        contact = np.unique(mine[touch & (h[mine] <= floor + CONTACT_BAND)])
        own = seg == b
        ratio = _extent(flat[contact]) / max(_extent(flat[own]), 1e-9)
        if ratio < NECK_RATIO and _over(flat[own].mean(axis=0), flat[seg == a], up):
            target[b] = a
            joins += 1
    return np.where(valid, target[np.maximum(seg, 0)], -1), joins


def _below_objects(seg: np.ndarray, h: np.ndarray, limit: float) -> np.ndarray:
    """Points of segments whose 95th-percentile height over the support plane is below `limit`."""
    out = np.zeros(len(seg), dtype=bool)
    if (seg >= 0).any():
        ids, inv = np.unique(seg[seg >= 0], return_inverse=True)
        out[seg >= 0] = (group_percentile(h[seg >= 0], inv.ravel(), len(ids), 95) < limit)[inv.ravel()]
    return out


def _on_support(seg: np.ndarray, h: np.ndarray | None, reach: np.ndarray | None, params: SegmentationParams
                ) -> np.ndarray:
    """Points of segments that belong to the support: never rising 2 x plane_distance over the support plane
    (h: heights over it, or None), or lying within STRUCT_REACH band half-widths of the room's structure
    (reach, or None)."""
    out = np.zeros(len(seg), dtype=bool)
    if h is not None:
        out |= _below_objects(seg, h, 2 * params.plane_distance)
    if reach is not None:
        out |= _below_objects(seg, np.minimum(reach, 1e6), STRUCT_REACH)  # finite: no inf x 0 in the percentile
    return out


def _plane_colour_refine(pts: np.ndarray, col: np.ndarray, labels: np.ndarray, plane: np.ndarray,
                         params: SegmentationParams) -> int:
    """Object points within plane_color_margin of the support plane whose colour is nearer the plane's mean
    colour than their segment's (by PLANE_COLOR_RATIO) join the plane (in place; returns how many). The fused surface rounds the
    corner where an object stands, so its foot is neither up-facing nor clearly the object: colour decides."""
    k = int(labels.max()) + 1
    if k <= 1:
        return 0
    obj = labels > 0
    mean = _mean_rows(col[labels >= 0], labels[labels >= 0], k)
    h = pts @ plane[:3] + plane[3]
    cand = np.flatnonzero(obj & (h < params.plane_color_margin))
    d_plane = np.linalg.norm(col[cand] - mean[PLANE_LABEL], axis=1)
    d_own = np.linalg.norm(col[cand] - mean[labels[cand]], axis=1)
    move = cand[d_plane < PLANE_COLOR_RATIO * d_own]
    labels[move] = PLANE_LABEL
    return int(len(move))


def _foot_refine(pts: np.ndarray, nrm: np.ndarray, labels: np.ndarray, plane: np.ndarray,
                 params: SegmentationParams) -> int:
    """Points at the objects' feet decided one by one (in place; returns how many changed label). The fused
    surface rounds the corner where an object stands, so its lowest points are neither clearly table nor clearly
    side; a point belongs to the surface it is nearest to: to the object when it rises more than foot_height
    (about half a voxel, the table's own spread) over the support plane or its normal is nearer the side's than the
    table's (bent more than foot_normal_deg from up), else to the support. Only points under FOOT_BAND within
    foot_radius of an object's side (its points above FOOT_BAND) are decided; they take that object's label."""
    h = pts @ plane[:3] + plane[3]
    side = np.flatnonzero((labels > 0) & (h > FOOT_BAND))
    cand = np.flatnonzero((labels >= 0) & (h <= FOOT_BAND))
    if len(side) == 0 or len(cand) == 0:
        return 0
    d, j = cKDTree(pts[side]).query(pts[cand], distance_upper_bound=params.foot_radius)
    near = np.isfinite(d)
    cand, j = cand[near], j[near]
    bent = nrm[cand] @ plane[:3] < np.cos(np.radians(params.foot_normal_deg))
    new = np.where((h[cand] > params.foot_height) | bent, labels[side[j]], PLANE_LABEL)
    changed = int(np.sum(new != labels[cand]))
    labels[cand] = new
    return changed


def _structure_foot_refine(pts: np.ndarray, labels: np.ndarray, height: np.ndarray, params: SegmentationParams
                           ) -> int:
    """Where furniture meets the room's structure, the structure's band (several cm on a far floor or wall)
    takes the furniture's foot too. A structure point higher than plane_distance over its plane's local median
    (height, nan off the structure) within foot_radius of an object point goes to that object; STRUCT_FOOT_ROUNDS
    rounds, each from the points joined before (in place; returns how many). The normals are no guide here:
    on the synthetic room's far floor half of them lean more than 40 deg (room seeds 0 and 1, boundary P / R with
    a 45 deg normal test 0.648 / 0.584 and 0.678 / 0.621, without one 0.769 / 0.609 and 0.766 / 0.653)."""
    moved = 0
    for _ in range(STRUCT_FOOT_ROUNDS):
        obj = np.flatnonzero(labels > 0)
        cand = np.flatnonzero((labels == PLANE_LABEL) & (height > params.plane_distance))
        if len(obj) == 0 or len(cand) == 0:
            break
        d, j = cKDTree(pts[obj]).query(pts[cand], distance_upper_bound=params.foot_radius)
        hit = np.isfinite(d)
        if not hit.any():
            break
        labels[cand[hit]] = labels[obj[j[hit]]]
        moved += int(hit.sum())
    return moved


def _room_structure(pts: np.ndarray, nrm: np.ndarray, good: np.ndarray, params: SegmentationParams
                    ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None, np.ndarray | None, dict | None]:
    """(mask, reach, height, floor, info) of the room's structure (structure.py) over all points; floor: its
    lowest plane facing up (within up_tolerance_deg), or None; all but info None when the scene is no room (info
    None when the search is off)."""
    if params.structure_planes <= 0:
        return None, None, None, None, None
    struct = find_structure(pts[good], nrm[good], max_planes=params.structure_planes,
                            min_extent=params.structure_min_extent, sigmas=params.structure_sigmas,
                            min_band=params.plane_distance, iterations=params.plane_iterations,
                            rng=np.random.default_rng(int(params.seed)))
    if not len(struct.planes):
        return None, None, None, None, struct.info
    n = len(pts)
    mask, reach, height = np.zeros(n, dtype=bool), np.full(n, np.inf), np.full(n, np.nan)
    mask[good], reach[good], height[good] = struct.mask, struct.reach, struct.height
    up = params.up_vector()
    floor = None
    if up is not None:
        facing = [p for p in struct.planes if p[:3] @ up >= np.cos(np.radians(params.up_tolerance_deg))]
        floor = max(facing, key=lambda p: float(p[3]), default=None)  # n . x = -d: the largest d is the lowest
    return mask, reach, height, floor, struct.info


def segment_cloud(points: np.ndarray, normals: np.ndarray, params: SegmentationParams | None = None,
                  colors: np.ndarray | None = None, space=None) -> Segmentation:
    """Segment a surface cloud (N, 3) with outward normals (N, 3) and, optionally, colours (N, 3) RGB in
    [0, 1] (None: the colour terms are off). See the module docstring. space: the volume's labels as a
    bridges.SpaceQuery (None: no bridges across unknown space)."""
    params = params or SegmentationParams()
    params.validate()
    pts = np.asarray(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or nrm.shape != pts.shape:
        raise VolumeError(f"surface cloud: points and normals must be (N, 3), got {pts.shape} and {nrm.shape}")
    col = None
    if colors is not None:
        col = np.asarray(colors, dtype=np.float64)
        if col.shape != pts.shape:
            raise VolumeError(f"surface cloud: colours must be (N, 3) like the points, got {col.shape}")
    good = np.all(np.isfinite(pts), axis=1) & np.all(np.isfinite(nrm), axis=1)
    if col is not None:
        good &= np.all(np.isfinite(col), axis=1)
    if good.sum() < params.min_segment_points:
        raise VolumeError(f"surface cloud has {int(good.sum())} valid points: too few to segment "
                          f"(need at least min_segment_points = {params.min_segment_points})")
    n = len(pts)
    labels = np.full(n, NOISE_LABEL, dtype=np.int64)
    search: dict = {}
    struct_mask, reach_all, struct_height, floor, structure_info = _room_structure(pts, nrm, good, params)
    plane, inl = detect_support_plane(pts[good], nrm[good], params, search, span_rule=struct_mask is None)
    on_plane = np.zeros(n, dtype=bool)
    on_plane[np.flatnonzero(good)[inl]] = True
    if struct_mask is not None:
        on_plane |= struct_mask
        if plane is None and floor is not None:  # a room whose floor is too little seen for the support's rule
            plane = floor
            search["from_structure"] = True
    rest = np.flatnonzero(good & ~on_plane)
    labels[on_plane] = PLANE_LABEL
    sv_all = np.full(n, -1, dtype=np.int64)
    stats = {"points": int(n), "plane_points": int(on_plane.sum()), "support_plane_search": search,
             "method": params.method, "colors": col is not None,
             "color_distance": params.color_distance}
    if structure_info is not None:
        stats["structure"] = structure_info
    if len(rest) == 0:
        return Segmentation(pts, nrm, labels, plane, sv_all, 0, stats, col)
    P, N = pts[rest], nrm[rest]
    C = None if col is None else col[rest]
    pairs = adjacency_pairs(P, params.adjacency_radius)
    if params.method == "flood-fill":
        seg, grow = flood_fill_segments(N, pairs, params, C)
        k = 0
    else:
        seg, sv, grow = lccp_segments(P, N, pairs, params, C)
        stepped = grounded = None
        if plane is not None:  # step cuts first: their pieces are two boxes side by side, not cut again
            seg, grow["step_cuts"], stepped = step_cuts(P, N, seg, pairs, plane, params)
            if params.step_min_height:  # objects side by side are the step cuts'; face-plane cuts lift one off
                grounded = P @ plane[:3] + plane[3] < 2 * params.plane_distance
        seg, grow["plane_cuts"] = concave_plane_cuts(P, N, seg, pairs, params, stepped, grounded)
        k = int(sv.max()) + 1
        sv_all[rest] = sv
    stats.update(grow)
    # segments that never rise above the support plane (its edges, legs) belong to the support: decided before
    # small segments merge (a speck of table edge must not join the object beside it) and again after
    if plane is not None or reach_all is not None:
        h = None if plane is None else P @ plane[:3] + plane[3]
        reach = None if reach_all is None else reach_all[rest]
        support = _on_support(seg, h, reach, params)
        seg = _absorb_small(np.where(support, -1, seg), pairs, params.min_segment_points)
        support |= _on_support(seg, h, reach, params)
        labels[rest[support]] = PLANE_LABEL
        seg = np.where(support, -1, seg)
        keep_rest = ~support
        if params.fragment_points > 0:
            near_plane = _near(P, pts[labels == PLANE_LABEL], params.adjacency_radius)
            seg, stats["fragments_merged"] = _merge_fragments(seg, pairs, near_plane, params.fragment_points,
                                                              params.fragment_share)
        if h is not None:
            seg, stats["floating_joined"] = _join_floating(seg, P, pairs, h, plane[:3])
            seg, stats["necks_joined"] = _join_necks(seg, P, pairs, h, plane[:3], params)
        if space is not None and params.bridge_gap > 0:
            seg, stats["bridges_joined"] = join_across_unknown(seg, P, N, C, space, params.adjacency_radius,
                                                               BridgeParams(max_gap=params.bridge_gap))
    else:
        seg = _absorb_small(seg, pairs, params.min_segment_points)
        keep_rest = np.ones(len(seg), dtype=bool)
    # relabel 1..K by decreasing size
    valid = (seg >= 0) & keep_rest
    ids, inv, counts = np.unique(seg[valid], return_inverse=True, return_counts=True)
    order = np.argsort(-counts, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    out = np.full(len(rest), NOISE_LABEL, dtype=np.int64)
    out[valid] = rank[inv.ravel()] + 1
    labels[rest[keep_rest]] = out[keep_rest]
    # leftover specks: on the support plane's level -> support; touching a segment -> that segment
    drop = np.flatnonzero(labels == NOISE_LABEL)
    if len(drop) and plane is not None:
        h = pts[drop] @ plane[:3] + plane[3]
        low = np.abs(h) < 2 * params.plane_distance
        labels[drop[low]] = PLANE_LABEL
        drop = drop[~low]
    if len(drop) and reach_all is not None:
        low = reach_all[drop] <= STRUCT_REACH
        labels[drop[low]] = PLANE_LABEL
        drop = drop[~low]
    if len(drop):
        lab_idx = np.flatnonzero(labels != NOISE_LABEL)
        if len(lab_idx):
            d, j = cKDTree(pts[lab_idx]).query(pts[drop], distance_upper_bound=params.adjacency_radius)
            hit = np.isfinite(d)
            labels[drop[hit]] = labels[lab_idx[j[hit]]]
    if col is not None and plane is not None and params.plane_color_margin > 0:
        stats["plane_color_points"] = _plane_colour_refine(pts, col, labels, plane, params)
    if plane is not None and params.foot_radius > 0:
        stats["foot_points"] = _foot_refine(pts, nrm, labels, plane, params)
    if reach_all is not None and params.foot_radius > 0:
        stats["structure_foot_points"] = _structure_foot_refine(pts, labels, struct_height, params)
    stats.update({"segments": int(len(ids)), "dropped_points": int(np.sum(labels == NOISE_LABEL))})
    return Segmentation(pts, nrm, labels, plane, sv_all, k, stats, col)
