"""Camera poses for fusion: the paper's hint modes (digest §1.5).

forced: the given pose (robot kinematics / TF), no tracking.
icp:    frame-to-model point-to-plane ICP, initialised with the previous estimate moved on at the
        camera's last velocity (constant-velocity prediction).
hint:   the same ICP, initialised with the given (TF) pose, on the finest pyramid level (HINT_ITERATIONS).
topic:  the pose from a PoseStamped/Odometry topic, no tracking (forced with another source).

Frame-to-model: the model is the volume ray cast from the initial pose, the data the new depth image in the
camera frame; ICP estimates T_world_camera directly. Two ICPs (parameter icp):
- "projective" (default): KinFu's tracker (fusion.icp): projective data association against the model's
  vertex / normal maps, cast only in a band around the frame's depths (fusion.raycast.band_raycast), on a
  3-level pyramid of the bilateral-filtered depth; 12-30x faster than open3d's (benchmarks/bench_tracking.py).
- "open3d": open3d's point-to-plane ICP on clouds (the reference).
Re-localisation (below) uses open3d's ICP in both cases.
With colour, projective ICP adds a photometric term against the last fused frame (fusion.photometric; keep_reference
makes a fused frame the next one's reference) at PHOTO_WEIGHT, capped at PHOTO_SHARE of the depth term's
translation information: depth alone slides along a wall-floor line (benchmarks/bench_room_drift.py, textured
seeds 0-3: ATE 2.1-2.5 cm, 25-29 of 200 frames re-localised; with the term 0.9-1.1 cm, 1 re-localised), and the
cap keeps rich real texture from overriding depth with colour's own errors (7-Scenes kitchen 0.67 / 0.66 cm;
uncapped 0.90 cm).

When is a frame lost? ICP always returns some pose; it is kept only when all the checks pass:
1. fitness (share of the frame's points with a model correspondence within the finest correspondence
   distance; projective ICP's also within its normal angle, so noisy far normals lower it: 0.44-0.50 on good
   Kinect v1 kitchen frames, against ~0.98 by distance alone, which kept the room walks' worse frames from the
   re-localisation that re-anchors them) >= min_fitness: less overlap than that cannot pin a pose down;
2. agreement >= min_agreement: where the frame and the model ray cast from the new pose both see a surface,
   the share of pixels whose depths differ by less than the volume's truncation distance (a reading within
   the truncation band updates the same surface; beyond, it would add a second one). At a right pose only
   noise, depth edges, occluders and moved objects disagree; a pose a few centimetres off moves whole walls
   out of the band. This is the check that catches ICP converging to a wrong pose with a fair fitness
   (projective ICP measures it against the model maps it tracked against, with no second ray cast);
3. the condition number of the point-to-plane 6x6 system at the pose <= max_condition (degenerate geometry
   such as a flat wall lets the pose slide along it: such a pose is a guess); open3d's ICP and re-localisation
   are checked with projective ICP's system at the pose they found;
4. the camera moved no faster than max_speed / max_turn since the last good pose (KinFu's per-frame ICP
   limits of 0.10 m and 20 degrees at 30 Hz, as speeds, so sub-sampled frames may move further);
5. hint mode: the pose lies within HINT_MAX_M / HINT_MAX_DEG of the TF pose (TrackResult.tf_disagrees when not:
   the only loss after which the fusion pipeline does not fall back to the TF pose).
When the first attempt fails, the tracker re-localises before declaring the frame lost: a wider
coarse-to-fine pyramid (30 cm correspondences on a 4 cm cloud down to the finest level) from each of the
candidate initial poses the caller gives (in icp mode the prediction and the last good pose; in hint mode the
TF hint and the last good pose); the best attempt that passes the checks wins.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from kinfu_cli.core.camera import is_resized
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.fusion.placement import backproject
from kinfu_cli.fusion.icp import EDGE_JUMP_PER_M, data_pyramid, model_agreement, projective_icp, vertex_normals
from kinfu_cli.fusion.photometric import PhotometricReference, intensity_pyramid
from kinfu_cli.fusion.raycast import BAND_HIT, BAND_OCCLUDED, band_cloud, band_raycast, model_cloud

POSE_MODES = ("forced", "icp", "hint", "topic")
ICP_METHODS = ("projective", "open3d")

# KinFu's ICP limits per frame (0.10 m, 20 degrees) at its 30 Hz, as speeds
MAX_SPEED_M_S = 0.10 * 30
MAX_TURN_DEG_S = 20.0 * 30
# re-localisation pyramid: correspondence distances (m), iterations and data-cloud voxel per level; the first
# level reaches 30 cm (a hand-held camera's motion over a few sub-sampled frames), the last is the tracker's finest
# projective ICP: the largest condition number of the 6x6 system (largest / smallest eigenvalue) trusted. Scenes
# with 3D structure measure 1e2-1e3 (7-Scenes kitchen median 160, the simulator's box scene 200-700); a flat
# wall filling a 160x120 view 3.8e3 (only its borders hold the slide along it)
MAX_CONDITION = 2.5e3
# the narrowest image (pixels) projective ICP's finest level and its model map are made at
MIN_ICP_WIDTH = 320
# ... and the narrowest model map (160 px, from 320 px frames, lost the sample recording's hint-mode track: 4 cm off)
MIN_MODEL_WIDTH = 320
# ICP tracking of depth frames narrower than this (px) is said to be doubtful (fusion.pipeline warns): their few
# pixels pin the pose down poorly in ways no loss check sees. Tracked in place on identical noise-free frames of the
# simulator's box scene (1 / 2 cm voxels, 8 frames), the camera drifted 1.5 / 3.1 cm at 64 px, 1.1 / 1.4 at 96,
# 1.8 / 2.3 at 128, 1.7 / 1.2 at 160, 0.9 / 0.4 at 240 and 0.2 / 0.5 at 320 px; a 64x48 table scene 46 cm
MIN_TRACKING_WIDTH = 160
# projective ICP re-casts the model map from the pose it found, and runs again from there, when that pose is further
# than this from the one the map was cast from (a large move, as between sub-sampled frames: the first map sees the
# scene from the wrong place, its occlusions and edges bias the association), at most RECASTS times
RECAST_M = 0.02
RECAST_DEG = 2.0
RECASTS = 0
# projective ICP stops iterating a pyramid level when one step moves the pose less than this (rad and m)
ICP_CONVERGED = 1e-4
# projective ICP's model maps as a share of the frame's size (never narrower than MIN_MODEL_WIDTH); KinFu casts them
# at full size
MAP_SCALE = 0.5
# projective ICP's model cast starts its march this many truncation distances in front of each reading where the
# model is free space there (band_raycast's `start`): a reading off by up to half a truncation still has its
# surface's whole truncation band ahead of the start; most rays then walk ~5 voxels instead of ~10 (0: the whole band)
BAND_START = 1.5
# the agreement check looks for the model surface within this many truncation distances of each reading
AGREEMENT_BAND = 4.0
RELOCALISE_LEVELS = ((0.30, 15, 0.04), (0.15, 15, 0.04), (0.08, 10, 0.02), (0.04, 10, 0.01))
# re-localisation's target is cast within this band (m) around each reading (band_raycast): wider than the coarsest
# level's correspondence distance, so every model point a reading could pair with is in it
RELOCALISE_MARGIN = 0.35
# re-localisation's data cloud takes every `stride`-th pixel, the stride raised until the cloud is at most this many
# pixels wide (every 4th of a 640 px frame, ~19k points; the finest levels' 1 cm voxel kept ~55k of every 2nd)
RELOCALISE_WIDTH = 160
# projective ICP from a measured pose (hint mode's TF): the finest level only, this many iterations (KinFu's count at
# its finest level). The coarse levels are there to converge from a constant-velocity guess after a large move; from
# a pose already within a centimetre or two they only add their own bias: on noisy depth they settle up to ~1 cm
# away along directions the scene holds weakly (a slide along the table), where the finest level, flat there, keeps
# it. The sample recording with its exact TF: 5.1 cm RMS from the TF poses with them, 0.44 cm without; with a
# hand-eye error of 1 / 2 cm both correct it alike (0.94 / 1.80 cm against 0.88 / 1.76 cm, from 1.52 / 3.04)
HINT_ITERATIONS = 10
# hint mode: a pose further than this from the TF pose is refused (the TF and ICP disagree: a robot's TF is good to a
# few centimetres; KinFu's per-frame ICP limit, 10 cm, as the bound). On the sample recording with a 2 m grid that cut
# its last views, re-localisation returned a pose 18 cm from the exact TF that passed every other check
HINT_MAX_M = 0.10
HINT_MAX_DEG = 10.0
# projective ICP's photometric term (fusion.photometric) weighs this much against the point-to-plane one: a grey
# residual r (0..1) costs as much as a point-to-plane distance of sqrt(PHOTO_WEIGHT) r metres (0.01 grey ~ 1.7 mm);
# chosen on the textured room walk (benchmarks/bench_room_drift.py --texture, seeds 0-1, 0.001-0.3)
PHOTO_WEIGHT = 0.03
# ... and it adds at most this share of the point-to-plane term's information on the translation: where colour is
# rich (a real kitchen: ~170x the depth term's), a colour term at full weight would override the depth term with
# colour's own errors (misregistration, unsynchronised streams); where depth cannot pin a slide, it holds it
PHOTO_SHARE = 0.1
# ... and no more than this (a grey residual of 0.1 would cost as much as a metre of depth)
MAX_PHOTO_WEIGHT = 100.0


# why a frame was lost, in a few words, by TrackResult.check
LOSS_CHECKS = {"depth": "too few depth points", "model": "model not in view", "fitness": "too little overlap",
               "agreement": "depth disagrees with the model", "condition": "flat view", "speed": "too fast",
               "tf": "far from the TF pose"}


@dataclass
class TrackResult:
    T_world_camera: np.ndarray  # the tracked pose; the (first) initial pose when lost
    fitness: float
    rmse: float
    lost: bool
    reason: str = ""
    agreement: float = float("nan")  # share of overlapping pixels whose depth agrees with the model
    relocalised: bool = False  # found by the wider re-localisation search, not the first attempt
    attempts: int = 1
    condition: float = float("nan")  # condition number of the point-to-plane 6x6 system at the pose
    tf_disagrees: bool = False  # lost by check 5: ICP found a pose far from the TF pose (hint mode)
    check: str = ""  # the check that lost it (LOSS_CHECKS), "" when kept
    photometric: bool = False  # the first (projective) attempt had the colour term (fusion.photometric), kept or not


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))


class FrameToModelTracker:
    """Point-to-plane ICP of a depth image against the volume's ray-cast surface.

    max_distances: coarse-to-fine correspondence distances (m); iterations per level; stride: pixel step
    for the data cloud; voxel: down-sampling of the data cloud (m); min_fitness, min_agreement, max_speed
    (m/s), max_turn (deg/s): the checks a pose must pass (module docstring); max_jump_m / max_jump_deg: the
    same limits per frame, used when the time since the last good pose is not known; model_scale: ray-cast
    image size for open3d's ICP target (and re-localisation's); agreement_stride: pixel step of the agreement
    check; relocalise: try the wider pyramid (RELOCALISE_LEVELS) from every candidate pose before declaring a
    frame lost.
    icp: "projective" or "open3d" (module docstring); max_distances / iterations / stride / voxel are open3d's.
    Projective ICP: projective_iterations per pyramid level (coarse to fine) with correspondences within
    projective_distance (m) and max_angle (deg) between normals; icp_scale: the finest data level as a share of
    the frame (never narrower than MIN_ICP_WIDTH); map_scale: the model maps' (MAP_SCALE); bilateral: filter the
    depth first (KinFu); band: half-width (m) of the model ray cast around each reading; band_start: where in the
    band its march starts (BAND_START, truncation distances in front of the reading); max_condition (module
    docstring, check 3); icp_converged: a pyramid level stops iterating when a step moves the pose less than
    this (rad and m); init_is_hint: the first initial pose is a measured one (hint mode's TF), and the first
    attempt runs the finest level only (HINT_ITERATIONS). photo_weight / photo_share: projective ICP's colour
    term (module docstring; 0: depth only). timing: seconds spent per phase (filter, pyramid, intensities,
    raycast, model normals, icp WxH per level: its iterations in one numba call, agreement), summed over the
    frames tracked.
    """

    def __init__(self, max_distances=(0.10, 0.05, 0.02), iterations=(10, 10, 8), stride: int = 2,
                 voxel: float = 0.01, min_fitness: float = 0.3, min_agreement: float = 0.75,
                 max_speed: float = MAX_SPEED_M_S, max_turn: float = MAX_TURN_DEG_S, max_jump_m: float = 0.10,
                 max_jump_deg: float = 20.0, model_scale: float = 0.5, min_points: int = 300,
                 agreement_stride: int = 4, relocalise: bool = True, icp: str = "projective",
                 bilateral: bool = True, band: float = 0.15, max_angle: float = 20.0,
                 max_condition: float = MAX_CONDITION, icp_scale: float = 0.5,
                 projective_iterations=(30, 15, 6), projective_distance: float = 0.10,
                 icp_converged: float = ICP_CONVERGED, map_scale: float = MAP_SCALE,
                 band_start: float = BAND_START, init_is_hint: bool = False, photo_weight: float = PHOTO_WEIGHT,
                 photo_share: float = PHOTO_SHARE):
        if len(max_distances) != len(iterations):
            raise ConfigError("tracker: max_distances and iterations must have the same length")
        if icp not in ICP_METHODS:
            raise ConfigError(f"tracker: icp must be one of {', '.join(ICP_METHODS)}, got {icp!r}", parameter="icp")
        self.icp = icp
        self.bilateral = bool(bilateral)
        self.band = float(band)
        self.max_angle = float(max_angle)
        self.max_condition = float(max_condition)
        self.icp_scale = float(icp_scale)
        self.projective_iterations = tuple(int(x) for x in projective_iterations)
        self.projective_distance = float(projective_distance)
        self.icp_converged = float(icp_converged)
        self.map_scale = float(map_scale)
        self.band_start = float(band_start)
        self.init_is_hint = bool(init_is_hint)
        self._hint: np.ndarray | None = None  # the current frame's TF pose (init_is_hint)
        self._frame_pyramid: tuple | None = None  # the current frame's data pyramid (_pyramid)
        self._last_pyramid: tuple | None = None  # (depth image, pyramid, f) of the frame tracked last
        self._color: tuple | None = None  # the current frame's (colour, colour mask), when it has colour
        self._reference: PhotometricReference | None = None  # the last fused frame (keep_reference)
        self.photo_weight = float(photo_weight)
        self.photo_share = float(photo_share)
        self.timing: dict[str, float] = {}  # seconds per phase of projective tracking, summed over the frames
        self.max_distances = tuple(float(x) for x in max_distances)
        self.iterations = tuple(int(x) for x in iterations)
        self.stride = int(stride)
        self.voxel = float(voxel)
        self.min_fitness = float(min_fitness)
        self.min_agreement = float(min_agreement)
        self.max_speed = float(max_speed)
        self.max_turn = float(max_turn)
        self.max_jump_m = float(max_jump_m)
        self.max_jump_deg = float(max_jump_deg)
        self.model_scale = float(model_scale)
        self.min_points = int(min_points)
        self.agreement_stride = int(agreement_stride)
        self.relocalise = bool(relocalise)

    def track(self, volume, depth: np.ndarray, K: np.ndarray, T_init, T_ref: np.ndarray | None = None,
              dt_s: float | None = None, color: np.ndarray | None = None,
              color_mask: np.ndarray | None = None) -> TrackResult:
        """ICP of `depth` (camera frame) against the volume's surface.

        T_init: the initial pose, or a sequence of candidate poses (the first is tried with the normal
        pyramid; all of them with the re-localisation pyramid when that fails). T_ref: the last good pose
        and dt_s the seconds since it, for the speed check (default: the first candidate, per-frame limits).
        color (RGB uint8, the depth image's pixels, at its size or resized) and color_mask (False: no sample):
        with a reference frame (keep_reference) and photo_weight > 0, projective ICP adds the photometric term.
        Lost: the first candidate pose is returned with lost=True and the reason.
        """
        inits = [np.asarray(T_init, dtype=np.float64)] if np.ndim(T_init) == 2 else \
            [np.asarray(T, dtype=np.float64) for T in T_init]
        # this frame's state, read by the checks and the attempts, gone when the call ends: the TF pose (check 5),
        # the data pyramid, built once (_pyramid), and the colour
        self._hint = inits[0] if self.init_is_hint else None
        self._frame_pyramid = None
        self._color = None if color is None else (color, color_mask)
        try:
            return self._track(volume, depth, K, inits, T_ref, dt_s)
        finally:  # the pyramid stays for keep_reference, with the image as the caller gave it
            self._last_pyramid = None if self._frame_pyramid is None else (depth, *self._frame_pyramid[:2])
            self._hint = self._frame_pyramid = self._color = None

    def keep_reference(self, volume, depth: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray,
                       color: np.ndarray | None, color_mask: np.ndarray | None = None) -> None:
        """The frame just fused at T_world_camera becomes the photometric reference of the next one (none without
        colour in the depth image's pixels, at its size or resized, or with photo_weight 0)."""
        self._reference = None
        if self.photo_weight <= 0 or color is None or not _depth_pixels(color, depth):
            return
        last = self._last_pyramid
        if last is not None and last[0] is depth:  # the frame just tracked: its pyramid
            _, pyr, f = last
        else:
            pyr, f, _ = self._pyramid(volume, depth, K)
            self._frame_pyramid = None
        self._last_pyramid = None
        shapes = [lev.depth.shape for lev in pyr[f:]]
        self._reference = PhotometricReference(intensity_pyramid(color, color_mask, shapes, gradients=True),
                                               [lev.depth for lev in pyr[f:]], np.asarray(T_world_camera, float))

    def _intensities(self, depth: np.ndarray, pyr: list, f: int):
        """The current frame's intensity levels for ICP's levels pyr[f:], or None when there is no photometric term
        (no colour, no reference, another image size)."""
        ref = self._reference
        if self.photo_weight <= 0 or self._color is None or ref is None:
            return None
        color, mask = self._color
        shapes = [lev.depth.shape for lev in pyr[f:]]
        if not _depth_pixels(color, depth) or shapes != [d.shape for d in ref.depths]:
            return None
        return intensity_pyramid(color, mask, shapes)

    def _track(self, volume, depth, K, inits: list[np.ndarray], T_ref, dt_s) -> TrackResult:
        """track() on the candidate list."""
        T_ref = inits[0] if T_ref is None else np.asarray(T_ref, dtype=np.float64)
        d = np.asarray(depth, dtype=np.float32)
        s = self.stride
        ds = d[::s, ::s]
        if np.count_nonzero((ds >= volume.min_depth) & (ds <= volume.max_depth)) < self.min_points:
            return TrackResult(inits[0].copy(), 0.0, float("nan"), True, "too few depth points", check="depth")
        h, w = depth.shape
        cache: dict = {}

        def source(voxel: float, stride: int):  # open3d's data cloud, every stride-th pixel, down-sampled to `voxel`
            import open3d as o3d  # heavy: only when tracking

            if ("cloud", stride) not in cache:
                pts = backproject(depth, K, np.eye(4), stride=stride, min_depth=volume.min_depth,
                                  max_depth=volume.max_depth)
                cache[("cloud", stride)] = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
            if (voxel, stride) not in cache:
                cloud = cache[("cloud", stride)]
                cache[(voxel, stride)] = cloud.voxel_down_sample(voxel) if voxel > 0 else cloud
            return cache[(voxel, stride)]

        def target(i: int, reloc: bool):  # the model seen from candidate i, cast when first needed; None: too little
            if ("target", i, reloc) not in cache:
                t = self._relocalise_target(volume, d, K, inits[i]) if reloc else None
                if t is None or len(t.points) < self.min_points:
                    # the full cast; for re-localisation when the model is nowhere near the readings (an occluder, a
                    # view past the model), where open3d's ICP on it tells "too little overlap" from "not in view"
                    if ("full", i) not in cache:
                        cache[("full", i)] = model_cloud(volume, K, w, h, inits[i], scale=self.model_scale)
                    t = cache[("full", i)]
                cache[("target", i, reloc)] = t if len(t.points) >= self.min_points else None
            return cache[("target", i, reloc)]

        # data-cloud voxel per level: `voxel`, or a quarter of the level's correspondence distance when coarser
        # (coarse levels need no dense cloud; the finest keeps `voxel`: at the model's 2 cm voxel a 2 cm cloud
        # tracked the 7-Scenes kitchen 1 mm worse)
        def level_voxel(dist: float) -> float:
            return max(self.voxel, dist / 4) if self.voxel > 0 else 0.0

        fine = [(d_, it, level_voxel(d_)) for d_, it in zip(self.max_distances, self.iterations)]
        best, attempts = None, 0
        if self.icp == "projective":
            best, attempts = self._projective_attempt(volume, d, K, inits[0], T_ref, dt_s), 1
            if best is None:
                attempts = 0
        photometric = best is not None and best.photometric
        plans = [(0, fine, False)] if self.icp == "open3d" else []
        if self.relocalise:
            coarse = [(d_, it, max(v, level_voxel(d_))) for d_, it, v in RELOCALISE_LEVELS
                      if d_ > self.max_distances[-1]] + fine[-1:]
            plans += [(i, coarse, True) for i in range(len(inits))]
        # re-localisation's data cloud: no wider than RELOCALISE_WIDTH pixels
        stride = {False: self.stride, True: max(self.stride, w // RELOCALISE_WIDTH)}
        # open3d's ICP on one thread: the same frames, the same poses (one_open3d_thread); none when nothing is left
        with one_open3d_thread() if plans and (best is None or best.lost) else nullcontext():
            for i, levels, reloc in plans:
                if best is not None and not best.lost:
                    break
                if target(i, reloc) is None:
                    continue
                attempts += 1
                res = self._attempt(lambda v: source(v, stride[reloc]), target(i, reloc), inits[i], levels, volume,
                                    depth, K, T_ref, dt_s, coarse_target=reloc)
                res.relocalised = reloc
                if best is None or _better(res, best):
                    best = res
        if best is None:
            return TrackResult(inits[0].copy(), 0.0, float("nan"), True, "model surface not visible", attempts=0,
                               check="model")
        best.attempts = attempts
        best.photometric = photometric
        if best.lost:
            best.T_world_camera = inits[0].copy()
        return best

    def _relocalise_target(self, volume, depth, K, T):
        """Re-localisation's target: the model seen from T at model_scale of the frame, cast only where the frame
        has a reading, within RELOCALISE_MARGIN of it (the full cast, model_cloud, costs ~3x more: every ray walks
        from min_depth)."""
        s = max(1, int(round(1 / self.model_scale)))
        hint = np.ascontiguousarray(depth[::s, ::s])
        hint = np.where((hint >= volume.min_depth) & (hint <= volume.max_depth), hint, np.float32(0))
        Ks = np.asarray(K, dtype=np.float64).copy()
        Ks[:2] /= s  # pixel (u, v) of the hint is pixel (s u, s v) of the frame
        return band_cloud(volume, Ks, T, hint, RELOCALISE_MARGIN,
                          start=self.band_start * volume.truncation if self.band_start > 0 else None)

    def _projective_attempt(self, volume, depth, K, T_init, T_ref, dt_s) -> TrackResult | None:
        """Projective ICP (fusion.icp) against the model maps ray cast from T_init, then the checks (the
        agreement against the same maps); None when the model shows too little from there."""
        pyr, f, m = self._pyramid(volume, depth, K)
        its = self.projective_iterations
        if self.init_is_hint:  # from the TF pose: the finest level only (HINT_ITERATIONS says why)
            its = (0,) * (len(its) - 1) + (HINT_ITERATIONS,)
        dists = (self.projective_distance,) * len(its)
        T_model = T_init
        t0 = time.perf_counter()
        gray = self._intensities(depth, pyr, f)
        if gray is not None:
            _add(self.timing, "intensities", time.perf_counter() - t0)
        for recast in range(1 + RECASTS):
            maps = self._model_maps(volume, pyr[m], T_model, m)
            if maps is None:
                return None
            mz, mv, mn, state = maps
            r = projective_icp(pyr[f:], mv, mn, pyr[m].K, T_model, r.T_world_camera if recast else T_init, its, dists,
                               self.max_angle, converged=self.icp_converged, timing=self.timing, intensities=gray,
                               reference=self._reference, photo_weight=self.photo_weight if gray else 0.0,
                               photo_share=self.photo_share)
            moved = np.linalg.inv(T_model) @ r.T_world_camera
            if np.linalg.norm(moved[:3, 3]) < RECAST_M and _angle_deg(moved[:3, :3]) < RECAST_DEG:
                break
            T_model = r.T_world_camera  # a large move: the model seen from where the camera turned out to be
        t0 = time.perf_counter()
        agreement = model_agreement(pyr[self._level(self.agreement_stride)], r.T_world_camera, mz, state, pyr[m].K,
                                    T_model, BAND_HIT, BAND_OCCLUDED, volume.truncation)
        _add(self.timing, "agreement", time.perf_counter() - t0)
        out = self._checked(r.T_world_camera, r.fitness, r.rmse, volume, depth, K, T_ref, dt_s, r.condition,
                            agreement)
        out.photometric = gray is not None
        return out

    def _pyramid(self, volume, depth, K) -> tuple[list, int, int]:
        """The frame's data pyramid, the finest level ICP uses and the level the model maps match: icp_scale /
        map_scale of the frame, but never narrower than MIN_ICP_WIDTH / MIN_MODEL_WIDTH pixels (a small frame is
        tracked at full size). Built once per frame: the first attempt and every re-localised pose's condition check
        share it."""
        if self._frame_pyramid is not None:
            return self._frame_pyramid
        f = min(self._level(1 / self.icp_scale), self._narrowest(depth.shape[1], MIN_ICP_WIDTH))
        levels = max(f + len(self.projective_iterations), self._level(self.agreement_stride) + 1)
        pyr = data_pyramid(depth, K, levels, volume.min_depth, volume.max_depth, self.bilateral,
                           first=min(f, self._level(self.agreement_stride)), timing=self.timing)
        m = min(self._level(1 / self.map_scale), self._narrowest(depth.shape[1], MIN_MODEL_WIDTH), levels - 1)
        self._frame_pyramid = (pyr, f, m)
        return self._frame_pyramid

    def _model_maps(self, volume, level, T_model, m: int):
        """(depth, vertex, normal, state) maps of the model ray cast from T_model at the pyramid level's size,
        within the band around its readings; None when they hold too few normals to track against."""
        t0 = time.perf_counter()
        mz, mv, _, state = band_raycast(volume, level.K, T_model, level.depth, self.band, tsdf_normals=False,
                                        start=self.band_start * volume.truncation if self.band_start > 0 else None)
        t1 = time.perf_counter()
        mn = vertex_normals(mv, mz, *T_model[:3, 3], EDGE_JUMP_PER_M)
        _add(self.timing, "raycast", t1 - t0)
        _add(self.timing, "model normals", time.perf_counter() - t1)
        if np.count_nonzero(np.isfinite(mn[..., 0])) < self.min_points // 4 ** m:
            return None
        return mz, mv, mn, state

    def _condition_at(self, volume, depth, K, T) -> float:
        """The condition number of the point-to-plane system at pose T, as projective ICP measures it (its finest
        level against the model maps cast from T): open3d's ICP (the reference, and re-localisation) reports
        none, and without it a frame of a flat wall slides along the wall unchecked; inf when the model shows too
        little from T."""
        pyr, f, m = self._pyramid(volume, depth, K)
        maps = self._model_maps(volume, pyr[m], T, m)
        if maps is None:
            return float("inf")
        _, mv, mn, _ = maps
        return projective_icp(pyr[f:f + 1], mv, mn, pyr[m].K, T, T, (0,), (self.projective_distance,),
                              self.max_angle).condition

    @staticmethod
    def _narrowest(width: int, min_width: int) -> int:
        """The coarsest pyramid level of a `width`-pixel frame still at least min_width pixels wide (0 at least)."""
        return max(0, int(np.floor(np.log2(max(width, 1) / min_width))))

    @staticmethod
    def _level(factor: float) -> int:
        """The pyramid level whose images are `factor` times smaller than the frame."""
        return max(0, int(round(np.log2(max(factor, 1.0)))))

    def _attempt(self, source, target, T_init, levels, volume, depth, K, T_ref, dt_s,
                 coarse_target: bool = False) -> TrackResult:
        """One open3d ICP run over `levels` ((distance, iterations, source voxel), coarse to fine), then the
        checks. coarse_target: the levels whose source voxel is coarser than `voxel` pair with the target
        down-sampled to it too (a target denser than the data cloud only makes each level's KD-tree dearer: at
        re-localisation's three coarse levels a quarter of its ICP time, for the same pose)."""
        import open3d as o3d  # heavy: only when tracking

        reg = o3d.pipelines.registration
        est = reg.TransformationEstimationPointToPlane()
        T = T_init.copy()
        res = None
        for dist, it, voxel in levels:
            tgt = target.voxel_down_sample(voxel) if coarse_target and voxel > self.voxel else target
            res = reg.registration_icp(source(voxel), tgt, dist, T, est,
                                       reg.ICPConvergenceCriteria(max_iteration=it))
            T = np.asarray(res.transformation).copy()
        return self._checked(T, float(res.fitness), float(res.inlier_rmse), volume, depth, K, T_ref, dt_s,
                             self._condition_at(volume, depth, K, T))

    def _checked(self, T, fitness, rmse, volume, depth, K, T_ref, dt_s, condition=float("nan"),
                 agreement=None) -> TrackResult:
        """The pose T with the loss checks (module docstring) applied; agreement: when already measured."""
        if agreement is None:
            agreement = self.agreement(volume, depth, K, T)
        out = TrackResult(T, fitness, rmse, False, "", agreement, condition=condition)
        moved = np.linalg.inv(T_ref) @ T
        step_m, step_deg = float(np.linalg.norm(moved[:3, 3])), _angle_deg(moved[:3, :3])
        if dt_s is not None and dt_s > 0:
            lim_m, lim_deg = self.max_speed * dt_s, self.max_turn * dt_s
        else:
            lim_m, lim_deg = self.max_jump_m, self.max_jump_deg
        if fitness < self.min_fitness:
            out.lost, out.check, out.reason = True, "fitness", f"fitness {fitness:.2f} < {self.min_fitness}"
        elif not agreement >= self.min_agreement:
            out.lost, out.check = True, "agreement"
            out.reason = f"depth agrees with the model on {agreement:.2f} < {self.min_agreement}"
        elif condition > self.max_condition:
            out.lost, out.check, out.reason = True, "condition", (f"the scene pins the pose down poorly (condition number {condition:.2g} > "
                                          f"{self.max_condition:.2g}: e.g. a flat wall)")
        elif step_m > lim_m or step_deg > lim_deg:
            out.lost, out.check, out.reason = True, "speed", (f"moved {step_m:.2f} m / {step_deg:.0f} deg since the last good pose "
                                          f"(limit {lim_m:.2f} m / {lim_deg:.0f} deg)")
        elif self._hint is not None:
            off = np.linalg.inv(self._hint) @ T
            off_m, off_deg = float(np.linalg.norm(off[:3, 3])), _angle_deg(off[:3, :3])
            if off_m > HINT_MAX_M or off_deg > HINT_MAX_DEG:
                out.lost, out.tf_disagrees, out.check = True, True, "tf"
                out.reason = (f"{off_m:.2f} m / {off_deg:.0f} deg from the TF pose (limit {HINT_MAX_M:.2f} m / "
                              f"{HINT_MAX_DEG:.0f} deg): TF and ICP disagree")
        return out

    def agreement(self, volume, depth: np.ndarray, K: np.ndarray, T_world_camera: np.ndarray) -> float:
        """Share of the pixels (every agreement_stride-th) with a reading where the model ray cast from
        T_world_camera also has a surface near it (in a band of a few truncations around the reading, or in front
        of it) whose depth is within the volume's truncation of the reading's; NaN when they share no pixel."""
        s = self.agreement_stride
        d = np.ascontiguousarray(np.asarray(depth, dtype=np.float32)[::s, ::s])
        d = np.where((d >= volume.min_depth) & (d <= volume.max_depth), d, np.float32(0))
        Ks = np.asarray(K, dtype=np.float64).copy()
        Ks[:2] /= s  # pixel (u, v) of this ray-cast image is pixel (s u, s v) of the depth image
        z, _, _, state = band_raycast(volume, Ks, T_world_camera, d, AGREEMENT_BAND * volume.truncation,
                                     tsdf_normals=False)
        both = (state == BAND_HIT) | (state == BAND_OCCLUDED)
        n = int(np.count_nonzero(both))
        if n == 0:
            return float("nan")
        return float(np.count_nonzero((state == BAND_HIT) & (np.abs(d - z) < volume.truncation)) / n)


def _depth_pixels(color: np.ndarray, depth: np.ndarray) -> bool:
    """Whether the colour image is the depth image's pixels: its size, or that size resized (a colour stream at
    twice the depth's resolution, a decimated depth; fusion resizes it so too). Another aspect ratio is another
    camera, whose pixels would need projecting."""
    return color.shape[:2] == depth.shape or is_resized(color.shape[1::-1], depth.shape[::-1])


@contextmanager
def one_open3d_thread() -> Iterator[None]:
    """open3d on one thread inside: its ICP sums the normal equations over oneTBB's threads in an order that
    changes from run to run, so the same frames gave poses differing in their last digits, and a re-localisation
    on the edge of a check went either way (room walks on depth alone: 1.8-3.4 cm over runs of one seed). One
    thread makes them repeat to the bit. Re-localisation is rare (~1 frame of 200 on the colour room walk) and
    open3d's ICP is ~3/4 of it, so the cost is small; open3d before 0.20 (OpenMP, no such control) stays as it was.
    The caller's own limit comes back afterwards."""
    import open3d as o3d  # heavy: only when tracking

    util = o3d.utility
    if not hasattr(util, "set_max_threads"):
        yield
        return
    before = util.get_max_threads()
    util.set_max_threads(1)
    try:
        yield
    finally:
        util.set_max_threads(before)


def _add(clock: dict, phase: str, seconds: float) -> None:
    clock[phase] = clock.get(phase, 0.0) + seconds


def _better(a: TrackResult, b: TrackResult) -> bool:
    """a beats b: a pose that passes beats one that does not, then the higher agreement, then fitness."""
    if a.lost != b.lost:
        return not a.lost
    ka = (np.nan_to_num(a.agreement, nan=-1.0), a.fitness)
    kb = (np.nan_to_num(b.agreement, nan=-1.0), b.fitness)
    return ka > kb


def predict_pose(T_prev: np.ndarray, T_prev2: np.ndarray | None, dt_prev_s: float | None,
                 dt_s: float | None) -> np.ndarray:
    """Constant-velocity prediction: T_prev moved on by the camera-frame motion from T_prev2 to T_prev, scaled
    to the time since T_prev (dt_s / dt_prev_s); T_prev when there is no earlier pose or no time."""
    if T_prev2 is None or not dt_prev_s or dt_s is None or dt_prev_s <= 0:
        return np.asarray(T_prev, dtype=np.float64).copy()
    step = np.linalg.inv(T_prev2) @ T_prev
    k = dt_s / dt_prev_s
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(k * Rotation.from_matrix(step[:3, :3]).as_rotvec()).as_matrix()
    out[:3, 3] = k * step[:3, 3]
    return np.asarray(T_prev, dtype=np.float64) @ out


def ate_rmse(estimated: list[np.ndarray], truth: list[np.ndarray]) -> float:
    """Absolute trajectory error (RMSE of camera positions, metres), both in the same world frame."""
    e = np.array([np.asarray(T)[:3, 3] for T in estimated])
    t = np.array([np.asarray(T)[:3, 3] for T in truth])
    return float(np.sqrt(np.mean(np.sum((e - t) ** 2, axis=1))))
