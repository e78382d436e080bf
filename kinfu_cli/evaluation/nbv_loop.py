"""`kinfu eval nbv`: the paper's Algorithm 1 in simulation, against random views and a fixed scan.

Given a `kinfu synth` ground truth (scene_before.ply, scene_after.ply, changes.json, camera_poses.txt,
hand.traj) or any mesh file:

1. initial scan: the recording's scan poses render the BEFORE scene with the simulated Kinect
   (`sim.sensor.DepthSensor`) and are fused into a ternary TSDF volume (`fusion.volume.TernaryVolume`);
2. the scene changes (the AFTER mesh is rendered from now on);
3. POIs from the simulated hand trajectory with GMM-AS (`attention.gmm_as`), or the true changes;
4. ForgetAround: every POI sphere is cleared to unknown;
5. per POI, per strategy, up to N views: rank the viewing sphere (`nbv.ranking.score_views`; by
   default `optimistic`: the initial scan leaves most of the space around the table unseen, and with
   the paper's rule those unknown voxels outside S(POI) would stop every ray from an unseen side;
   sensor positions in unknown space are allowed, the simulated arm has no planner),
   move there, oscillate +-`oscillation` deg about the camera's horizontal axis, fuse, re-rank.
   ``poi`` takes the best view not yet attempted and stops when the best gain < IncTh (Alg. 1);
   ``random`` takes a random valid candidate; ``fixed`` a predefined ring of views (latitude 40 deg,
   evenly spread longitudes), both for the same number of views. KFOVP fuses only at the views;
   KFOM also along the straight path between consecutive views (every `path_step` metres).

Reported: unknown voxels in each POI sphere after every view (the paper's Fig. 20), views until
IncTh, the final reconstruction error inside the POI spheres against the true after-change mesh
(accuracy: reconstructed surface to truth; completeness: true surface within `threshold` of the
reconstruction), and the time per stage.

``objects`` / ``standard`` (`run_exploration`, thesis ch. 3 Table 3.1 / Fig. 3.17) are POI-free: from a
short one-sided scan (no change, no ForgetAround) each takes views through the same `_take_view` path and
the same ray caster; ``objects`` plans with `nbv.objects.plan_object_views` (most salient segment's
contour viewpoints, scored on its bounding sphere + 0.2 m), ``standard`` with `plan_standard_views`
(every contour viewpoint scored on the whole volume). Reported: unknown voxels inside the true objects'
bounding spheres + `near_margin` after each view, candidate views ray-cast and planning time per view,
and the candidates each strategy needed to reach the same unknown count (`compare_exploration`).

Why the earlier object-driven loop stalled (measured, see the report of the objects-loop task): it rendered
the scene without surroundings, so rays into the void returned no depth and carved nothing while the
ray caster counted them as revealing unknown voxels (the chosen view scored ~1,300 rays and changed
~300 voxels); it also rejected candidates with the sensor in unknown space (after a one-sided scan that
is most of them) and stopped rays at unknown voxels outside the segment's sphere. Here the scene is
rendered inside a room (`room`), candidates in unknown space are allowed (`reject_unknown`, the simulated
arm has no planner) and rays pass unknown space outside the region (`optimistic`); views within
`exclude_shift` / `exclude_turn_deg` of one already taken are skipped, as the paper skips attempted views.

`run_loop(scene, LoopConfig(...))` is the driver; it returns the JSON-ready results document. Its tables are
`evaluation.tables.nbv_loop_table`, its plot `report.eval_nbv_plot`; `compare_strategies` runs the exploration on
a generated scenario (no files), for tests and benchmarks.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation, Slerp

from kinfu_cli.attention.gmm_as import GmmActivitySaliency
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.errors import ConfigError, RecordingError
from kinfu_cli.core.grid import TernaryGrid
from kinfu_cli.core.pois import DEFAULT_RADIUS
from kinfu_cli.core.progress import progress
from kinfu_cli.core.trials import TrialMap, serial_trials
from kinfu_cli.io.messages import c_stderr_silenced
from kinfu_cli.io.mesh_faces import faces_outside_vertices
from kinfu_cli.evaluation.reconstruction import point_to_mesh_distance
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.nbv.gains import get_gain
from kinfu_cli.nbv.objects import known_grid, nbv_scorer, plan_object_views, plan_standard_views, volume_contours
from kinfu_cli.nbv.ranking import default_inc_th, score_views, unknown_in_sphere
from kinfu_cli.nbv.sensor import MAX_IMAGE_PIXELS
from kinfu_cli.nbv.viewpoints import sphere_viewpoints
from kinfu_cli.segmentation.pipeline import SegmentOptions, analyse_volume
from kinfu_cli.sim.sampling import sample_triangles, surface_area
from kinfu_cli.sim.scenario import load_ground_truth, make_scenario
from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

EXPLORE = ("objects", "standard")
STRATEGIES = ("poi", "random", "fixed") + EXPLORE
MODES = ("kfovp", "kfom")


@dataclass
class LoopConfig:
    """Closed-loop parameters. voxel_size: the simulation volume (coarser than 512^3 by default);
    width/height: sensor image (default: the scene's camera); sphere: viewing-sphere kwargs."""

    strategies: tuple[str, ...] = STRATEGIES
    modes: tuple[str, ...] = ("kfovp",)
    views: int = 5
    voxel_size: float = 0.01
    gain: str = "unknown"
    inc_th: float | None = None
    poi_radius: float = DEFAULT_RADIUS
    pois_from: str | None = None  # gmm-as or truth for a kinfu synth folder; None: gmm-as (a bare mesh takes poi)
    oscillation_deg: float = 5.0
    path_step: float = 0.1
    scan_every: int = 1
    width: int | None = None
    height: int | None = None
    noise: bool = True
    seed: int = 0
    threshold: float = 0.01
    sphere: dict = field(default_factory=dict)
    poi: tuple[float, float, float] | None = None
    room: float = 5.0
    reject_unknown: bool = False
    optimistic: bool = True
    # POI-free exploration (strategies objects / standard)
    scan_frames: int = 8
    near_margin: float = 0.2
    score_width: int = 80
    score_fraction: float = 0.01
    exclude_shift: float = 0.05
    exclude_turn_deg: float = 10.0
    # frames fused at each view of the contour strategies: their contours apply the thesis' W_th = 5 (a voxel is
    # known once seen 5 times), which KinFu reaches by fusing every frame at 30 Hz while the robot holds the
    # view and oscillates; 9 frames over the oscillation sweep stand for that dwell (3 frames, the POI loop's
    # left-centre-right, could never make a voxel known from one view)
    explore_view_frames: int = 9

    def check(self) -> None:
        """ConfigError naming the first field out of range (and the gain when it is unknown)."""
        if not self.strategies:  # "," splits to nothing: a run of no strategy is no comparison
            raise ConfigError(f"expected at least one of {', '.join(STRATEGIES)}", parameter="strategies")
        for s in self.strategies:
            if s not in STRATEGIES:
                raise ConfigError(f"expected some of {', '.join(STRATEGIES)}, got {s!r}", parameter="strategies")
        for m in self.modes:
            if m not in MODES:
                raise ConfigError(f"expected some of {', '.join(MODES)}, got {m!r}", parameter="modes")
        explore = [s in EXPLORE for s in self.strategies]
        if any(explore) and not all(explore):
            raise ConfigError("objects and standard (POI-free exploration) cannot be mixed with poi, random or "
                              f"fixed, got {','.join(self.strategies)}", parameter="strategies")
        check_number(self.views, "views", 1, 1000, integer=True)
        if not (0.002 <= self.voxel_size <= 0.1):
            raise ConfigError(f"expected 0.002 to 0.1 m, got {self.voxel_size}", parameter="voxel_size")
        if self.pois_from is not None and self.pois_from not in ("gmm-as", "truth"):
            raise ConfigError(f"expected gmm-as or truth, got {self.pois_from!r}", parameter="pois_from")
        if self.pois_from is not None and all(explore):  # recorded in the result but not used
            raise ConfigError(f"the POI-free exploration ({','.join(self.strategies)}) finds no POIs; the POI "
                              f"source is for poi, random or fixed on a kinfu synth folder", parameter="pois_from")
        if self.scan_every < 1:
            raise ConfigError(f"expected at least 1, got {self.scan_every}", parameter="scan_every")
        check_number(self.explore_view_frames, "explore_view_frames", 1, 1000, integer=True)
        if self.scan_frames < 1:
            raise ConfigError(f"expected at least 1, got {self.scan_frames}", parameter="scan_frames")
        if self.score_width < 8:
            raise ConfigError(f"expected at least 8 pixels, got {self.score_width}", parameter="score_width")
        check_number(self.near_margin, "near_margin", 0, 10, unit="m")
        check_number(self.seed, "seed", 0, 2 ** 63 - 1, integer=True)
        for name in ("width", "height"):  # None: the scene's camera; 0 is not "default"
            if getattr(self, name) is not None:
                check_number(getattr(self, name), name, 8, 8192, integer=True, unit="pixels")
        if self.width is not None and self.height is not None:
            _check_image_size(self.width, self.height, "the given")
        check_number(self.oscillation_deg, "oscillation_deg", 0, 45, unit="degrees")
        check_number(self.poi_radius, "poi_radius", 0, 100, low_open=True, unit="m")
        if self.inc_th is not None:
            check_number(self.inc_th, "inc_th", 0)
        get_gain(self.gain)


@dataclass
class SimScene:
    """What the loop needs from a scene: meshes before/after, camera, initial-scan poses, hand, truth."""

    name: str
    before: o3d.geometry.TriangleMesh
    after: o3d.geometry.TriangleMesh
    K: np.ndarray
    width: int
    height: int
    scan_poses: np.ndarray
    hand: object | None
    changes: np.ndarray
    table_z: float | None
    box_lo: np.ndarray
    box_hi: np.ndarray
    render_before: object = None
    render_after: object = None
    object_spheres: np.ndarray | None = None  # (n, 4): centre and radius of each true object present after


def load_scene(path: str | os.PathLike, cfg: LoopConfig) -> SimScene:
    """A `kinfu synth` ground-truth folder (or the recording folder holding it), or a mesh file."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such scene (expected a kinfu synth ground_truth folder or a mesh file)")
    if path.is_dir():
        if cfg.poi is not None:  # recorded in the result but not used, it would read as the POI looked at
            if all(s in EXPLORE for s in cfg.strategies):
                raise ConfigError(f"the POI-free exploration ({','.join(cfg.strategies)}) takes no POI; the POI "
                                  f"position is for poi, random or fixed on a bare mesh SCENE", parameter="poi")
            raise ConfigError(f"{path}: a kinfu synth folder brings its POIs (from {cfg.pois_from or 'gmm-as'}); "
                              f"give the POI position only for a bare mesh SCENE", parameter="poi")
        gt = load_ground_truth(path)
        table = gt.info.get("table", {})
        cx, cy = table.get("center", [0.0, 0.0])
        sx, sy = table.get("size", [1.2, 0.8])
        tz = float(table.get("top_z", 0.7))
        lo = np.array([cx - sx / 2 - 0.3, cy - sy / 2 - 0.3, tz - 0.3])
        hi = np.array([cx + sx / 2 + 0.3, cy + sy / 2 + 0.3, tz + 0.9])
        n_scan = int(gt.info.get("frames", {}).get("scan") or len(gt.poses))
        present = {o["id"] for o in gt.objects if o.get("present_after", True)}
        spheres = bounding_spheres([m for k, m in gt.object_meshes().items() if k in present])
        # no hand.traj (removed, or a folder another tool wrote): run_loop says the POIs come from the truth
        hand = gt.hand() if (gt.folder / "hand.traj").exists() else None
        return SimScene(gt.folder.name, gt.mesh("before"), gt.mesh("after"), gt.K, gt.width, gt.height,
                        gt.poses[:n_scan:cfg.scan_every], hand, gt.change_positions, tz, lo, hi,
                        object_spheres=spheres)
    # no reader chatter (open3d warnings, RPly's own lines on a damaged PLY): we report problems
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error), c_stderr_silenced():
        mesh = o3d.io.read_triangle_mesh(str(path))
    if len(mesh.triangles) == 0:
        raise RecordingError(f"{path}: not a triangle mesh (no triangles)")
    if (outside := faces_outside_vertices(len(mesh.vertices), np.asarray(mesh.triangles))) is not None:
        raise RecordingError(f"{path}: {outside}")
    if cfg.pois_from is not None:  # neither a hand trajectory nor true changes: it would read as the POIs' source
        raise ConfigError(f"{path}: a bare mesh has no hand trajectory (gmm-as) nor true changes (truth) to find "
                          f"POIs from; give the POI position instead, or a kinfu synth folder as SCENE",
                          parameter="pois_from")
    if cfg.poi is None and not all(s in EXPLORE for s in cfg.strategies):  # the exploration says why it cannot
        raise ConfigError(f"{path}: a bare mesh has no hand trajectory; give the POI position (x, y, z)",
                          parameter="poi")
    bb = mesh.get_axis_aligned_bounding_box()
    lo, hi = np.asarray(bb.min_bound) - 0.3, np.asarray(bb.max_bound) + 0.3
    centre = (np.asarray(bb.min_bound) + np.asarray(bb.max_bound)) / 2
    scan = sphere_viewpoints(centre, radius=float(np.linalg.norm(hi - lo)) / 2 + 0.3, lon_step=45, lat_min=30,
                             lat_max=30, roll_step=360)
    K = kinect_v1_intrinsics(320, 240)
    poi = np.asarray(cfg.poi if cfg.poi is not None else [], dtype=float).reshape(-1, 3)
    return SimScene(path.stem, mesh, mesh, K, 320, 240, scan, None, poi, None, lo, hi)


def bounding_spheres(meshes) -> np.ndarray:
    """(n, 4) centre (of the axis-aligned box) and radius (farthest vertex) of each mesh."""
    out = []
    for m in meshes:
        v = np.asarray(m.vertices, dtype=np.float64)
        if len(v):
            c = (v.min(axis=0) + v.max(axis=0)) / 2
            out.append([*c, float(np.max(np.linalg.norm(v - c, axis=1)))])
    return np.array(out, dtype=np.float64).reshape(-1, 4)


def scene_from_scenario(seed: int = 0, **kwargs) -> SimScene:
    """A SimScene from `kinfu_cli.sim.scenario.make_scenario(seed, **kwargs)` (no files needed)."""
    sc = make_scenario(seed, **kwargs)
    t = sc.scene_before.table
    cx, cy = t.center[0], t.center[1]
    sx, sy = t.size[0], t.size[1]
    tz = float(t.top_z)
    lo = np.array([cx - sx / 2 - 0.3, cy - sy / 2 - 0.3, tz - 0.3])
    hi = np.array([cx + sx / 2 + 0.3, cy + sy / 2 + 0.3, tz + 0.9])
    scan = np.array([f.T_world_camera for f in sc.frames if f.phase == "scan"])
    return SimScene(f"scenario-{seed}", sc.scene_before.mesh(), sc.scene_after.mesh(), sc.K, sc.width, sc.height,
                    scan, sc.hand, np.array([c["position"] for c in sc.changes if "position" in c]).reshape(-1, 3),
                    tz, lo, hi, object_spheres=bounding_spheres([o.mesh for o in sc.scene_after.present_objects]))


def _with_room(mesh, centre: np.ndarray, size: float):
    """`mesh` plus the walls, floor and ceiling of a size x size x 3 m room around `centre` (rendering only):
    in the paper's lab every ray ends on something, and KinFu only carves along rays with a depth reading."""
    room = o3d.geometry.TriangleMesh.create_box(size, size, 3.0)
    room.translate([centre[0] - size / 2, centre[1] - size / 2, -0.01])
    room.paint_uniform_color([0.8, 0.8, 0.75])
    out = o3d.geometry.TriangleMesh(mesh)
    if not out.has_vertex_colors():
        out.paint_uniform_color([0.6, 0.6, 0.6])
    return out + room


def _scaled_K(K: np.ndarray, w0: int, h0: int, w: int, h: int) -> np.ndarray:
    """K for the image resized from w0 x h0 to w x h (pixel-centre convention)."""
    K = np.array(K, dtype=float)
    if (w, h) == (w0, h0):
        return K
    sx, sy = w / w0, h / h0
    K[0, 0] *= sx
    K[1, 1] *= sy
    K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    return K


def _tilt(T: np.ndarray, deg: float) -> np.ndarray:
    """T rotated by `deg` about its own x (horizontal image) axis."""
    a = math.radians(deg)
    R = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    out = T.copy()
    out[:3, :3] = T[:3, :3] @ R
    return out


def _path(T0: np.ndarray, T1: np.ndarray, step: float) -> list[np.ndarray]:
    """Poses strictly between T0 and T1 on the straight line (slerped orientation), every `step` m."""
    dist = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
    n = int(dist // step)
    if n < 1:
        return []
    s = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]])))
    out = []
    for k in range(1, n + 1):
        f = k / (n + 1)
        T = np.eye(4)
        T[:3, :3] = s([f]).as_matrix()[0]
        T[:3, 3] = (1 - f) * T0[:3, 3] + f * T1[:3, 3]
        out.append(T)
    return out


def _initial_scan(sc: SimScene, cfg: LoopConfig, sensor, K: np.ndarray, poses, mesh, name: str, quiet: bool):
    """Render and fuse the initial scan over the scene box -> (volume, views that saw something);
    RecordingError when none did."""
    vol = TernaryVolume(size=tuple(sc.box_hi - sc.box_lo), voxel_size=cfg.voxel_size, origin=tuple(sc.box_lo),
                        min_depth=sensor.min_range, max_depth=sensor.max_range, color=False)
    n_int = 0
    for i, T in enumerate(progress(poses, total=len(poses), desc="initial scan", quiet=quiet)):
        depth, _ = sensor.render(mesh, T, frame_seed=i)
        if np.any(depth > 0):
            vol.integrate(depth, K, T)
            n_int += 1
    if n_int == 0:
        raise RecordingError(f"{name}: the initial scan saw nothing (no valid depth in {len(poses)} views)")
    return vol, n_int


@dataclass
class LoopTrials:
    """What every trial of one run shares: the config, the volume after the initial scan (and ForgetAround),
    the POIs, and how to get the scene. It pickles without the scene (open3d meshes do not pickle): a worker
    process rebuilds it once with `load` and keeps it for its later trials; progress bars stay off there."""

    cfg: LoopConfig
    base: TernaryVolume
    load: object  # () -> SimScene, a picklable callable (functools.partial of a module-level function)
    pois: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    scene: tuple | None = None  # (SimScene, sensor, K, camera) once set up in this process
    quiet: bool = True

    def __getstate__(self) -> dict:
        return {**self.__dict__, "scene": None, "quiet": True}

    def setup(self) -> tuple:
        """(SimScene, DepthSensor, K, CameraModel), built on first use in this process."""
        if self.scene is None:
            sc = self.load()
            self.scene = (sc, *_sensor_setup(sc, self.cfg))
        return self.scene


def _strategy_trial(trials: LoopTrials, item: tuple[str, str]) -> tuple[dict, dict]:
    """One (strategy, mode) of the POI loop from a copy of the shared volume -> (its result, its timings)."""
    strat, mode = item
    sc, sensor, K, cam = trials.setup()
    timer = _Timer()
    run = _run_strategy(strat, mode, trials.base.copy(), trials.pois, sc, trials.cfg, sensor, K, cam,
                        dict(trials.cfg.sphere), sc.table_z, timer)
    return run, timer.t


class _Timer:
    def __init__(self) -> None:
        self.t: dict[str, float] = {}

    def add(self, key: str, dt: float) -> None:
        self.t[key] = self.t.get(key, 0.0) + dt


def run_loop(scene_path: str | os.PathLike, cfg: LoopConfig, quiet: bool = True,
             map_trials: TrialMap | None = None) -> dict:
    """Run the closed loop; returns the result document (see the module docstring). map_trials: run the
    (strategy, mode) trials through this map (a Dask cluster) instead of one after the other here; each is
    independent and seeded, so the document is the same (its timings aside)."""
    cfg.check()
    if cfg.strategies and all(s in EXPLORE for s in cfg.strategies):
        return run_exploration(load_scene(scene_path, cfg), cfg, quiet=quiet, scene_name=str(scene_path),
                               map_trials=map_trials, load=partial(load_scene, scene_path, cfg))
    timer = _Timer()
    t0 = time.perf_counter()
    sc = load_scene(scene_path, cfg)
    warnings = _pois_source_warnings(sc, cfg, scene_path)
    sensor, K, cam = _sensor_setup(sc, cfg)
    timer.add("load", time.perf_counter() - t0)

    # 1. initial scan of the scene before the change
    t = time.perf_counter()
    base, n_int = _initial_scan(sc, cfg, sensor, K, sc.scan_poses, sc.render_before, str(scene_path), quiet)
    timer.add("initial_scan", time.perf_counter() - t)

    # 2-3. the change happened; POIs from the hand trajectory
    t = time.perf_counter()
    pois = _find_pois(sc, cfg)
    inside = [p for p in pois if np.all(p >= base.origin) and np.all(p < base.origin + np.array(base.shape) * base.voxel_size)]
    if not inside:
        found_by = ((cfg.pois_from or "gmm-as") if sc.hand is not None else
                    "the given POI position" if cfg.poi is not None else "truth")
        raise ConfigError(f"{scene_path}: no POI inside the simulated volume ({len(pois)} found by {found_by})")
    pois = np.array(inside)
    timer.add("pois", time.perf_counter() - t)

    # 4. ForgetAround
    t = time.perf_counter()
    for p in pois:
        base.clear_sphere(p, cfg.poi_radius)
    timer.add("clear", time.perf_counter() - t)

    trials = LoopTrials(cfg, base, partial(load_scene, scene_path, cfg), pois=pois, scene=(sc, sensor, K, cam))
    items = [(strat, mode) for mode in cfg.modes for strat in cfg.strategies]
    runs = {}
    for (strat, mode), (run, times) in zip(items, (map_trials or serial_trials)(_strategy_trial, items, trials)):
        runs[strat if len(cfg.modes) == 1 else f"{strat}-{mode}"] = run
        for k, v in times.items():
            timer.add(k, v)
    doc = {
        "scene": str(scene_path), "config": _cfg_doc(cfg, sc), "camera": cam.to_dict(),
        "volume": {"shape": list(base.shape), "voxel_size": base.voxel_size, "origin": base.origin.tolist()},
        "initial_scan_views": int(n_int),
        "pois": [{"id": i, "position": p.tolist(),
                  "distance_to_nearest_change": float(np.min(np.linalg.norm(sc.changes - p, axis=1)))
                  if len(sc.changes) else None} for i, p in enumerate(pois)],
        "strategies": runs,
        "time_s": {k: round(v, 3) for k, v in timer.t.items()},
        "warnings": warnings,
    }
    doc["time_s"]["total"] = round(time.perf_counter() - t0, 3)
    return doc


def _pois_source_warnings(sc: SimScene, cfg: LoopConfig, scene_path) -> list[str]:
    """A kinfu synth folder without a hand trajectory has its POIs from the true changes: a warning when the
    source was left to its default (gmm-as), ConfigError when gmm-as was asked for (it would read as GMM-AS's)."""
    if sc.hand is not None or cfg.poi is not None or cfg.pois_from == "truth":
        return []
    if cfg.pois_from == "gmm-as":
        raise ConfigError(f"{scene_path}: the kinfu synth folder has no hand trajectory (hand.traj) for GMM-AS to "
                          f"find POIs in; give truth to take the true changes", parameter="pois_from")
    return [f"{scene_path}: the POIs are the {len(sc.changes)} true changes, not GMM-AS's (the default "
            f"pois_from gmm-as): the kinfu synth folder has no hand trajectory (hand.traj)"]


def _cfg_doc(cfg: LoopConfig, sc: SimScene | None = None) -> dict:
    d = asdict(cfg)
    d["strategies"] = list(cfg.strategies)
    d["modes"] = list(cfg.modes)
    if d["pois_from"] is None:  # the source the run used: gmm-as unless a bare mesh's given position or no hand
        d["pois_from"] = ("poi" if cfg.poi is not None else
                          "truth" if sc is not None and sc.hand is None else "gmm-as")
    return d


def _find_pois(sc: SimScene, cfg: LoopConfig) -> np.ndarray:
    if cfg.pois_from == "truth" or sc.hand is None:
        return np.asarray(sc.changes, dtype=float).reshape(-1, 3)
    det = GmmActivitySaliency(radius=cfg.poi_radius).fit(sc.hand)
    return np.array([p.position for p in det.pois_], dtype=float).reshape(-1, 3)


def _fixed_ring(cands: np.ndarray, center: np.ndarray, n: int) -> list[int]:
    """Candidate indices of a predefined ring: latitude nearest 40 deg, roll 0, n evenly spread longitudes."""
    rel = cands[:, :3, 3] - center
    lat = np.degrees(np.arcsin(np.clip(rel[:, 2] / np.linalg.norm(rel, axis=1), -1, 1)))
    lon = np.degrees(np.arctan2(rel[:, 1], rel[:, 0])) % 360
    best_lat = lat[np.argmin(np.abs(lat - 40))]
    ring = np.flatnonzero(np.isclose(lat, best_lat))
    out = []
    for k in range(n):
        target = (360.0 * k / n) % 360
        dl = np.abs((lon[ring] - target + 180) % 360 - 180)
        cand = ring[np.argsort(dl, kind="stable")]
        cand = [c for c in cand if c not in out]
        if cand:
            out.append(int(cand[0]))
    return out


def _take_view(vol, T_cur, T_goal, mode, sc, cfg, sensor, K, timer, frames: int,
               view_frames: int | None = None) -> int:
    """Move to T_goal (KFOM: fusing along the straight path), oscillate, render the after scene, fuse.
    view_frames: frames fused at the view, spread evenly over the oscillation sweep; None: left, centre and
    right (the centre alone without oscillation). Returns the updated count of frames fused."""
    poses = _path(T_cur, T_goal, cfg.path_step) if mode == "kfom" else []
    osc = cfg.oscillation_deg
    if view_frames is None:
        poses += [T_goal] if osc <= 0 else [_tilt(T_goal, -osc), T_goal, _tilt(T_goal, osc)]
    else:
        poses += [_tilt(T_goal, a) if a else T_goal for a in np.linspace(-osc, osc, view_frames)]
    for T in poses:
        t = time.perf_counter()
        depth, _ = sensor.render(sc.render_after, T, frame_seed=10_000 + frames)
        timer.add("render", time.perf_counter() - t)
        t = time.perf_counter()
        if np.any(depth > 0):
            vol.integrate(depth, K, T)
        timer.add("integrate", time.perf_counter() - t)
        frames += 1
    return frames


def _check_image_size(width: int, height: int, source: str) -> None:
    """The bound `kinfu nbv` puts on a sensor image (nbv.sensor.MAX_IMAGE_PIXELS): a larger one takes tens of
    GB to cast and fuse."""
    if width * height > MAX_IMAGE_PIXELS:
        side = math.isqrt(MAX_IMAGE_PIXELS)
        raise ConfigError(f"{source} image size {width}x{height} px holds {width * height:,} pixels, more than "
                          f"the {MAX_IMAGE_PIXELS:,} ({side}x{side}) an NBV sensor may have", parameter="width/height")


def _sensor_setup(sc: SimScene, cfg: LoopConfig):
    """Room-enclosed render meshes, the simulated sensor and the NBV camera model (same image, same ranges)."""
    centre = (sc.box_lo + sc.box_hi) / 2
    sc.render_before = _with_room(sc.before, centre, cfg.room) if cfg.room > 0 else sc.before
    sc.render_after = _with_room(sc.after, centre, cfg.room) if cfg.room > 0 else sc.after
    w = cfg.width or sc.width
    h = cfg.height or sc.height
    _check_image_size(w, h, "the given" if cfg.width and cfg.height else f"scene {sc.name}: the sensor's")
    K = _scaled_K(sc.K, sc.width, sc.height, w, h)
    sensor = DepthSensor(K, w, h, noise=cfg.noise, seed=cfg.seed)
    cam = CameraModel(K[0, 0], K[1, 1], K[0, 2], K[1, 2], w, h, min_range=sensor.min_range,
                      max_range=sensor.max_range, vfov_extra_deg=cfg.oscillation_deg)
    return sensor, K, cam


def near_object_voxels(grid: TernaryGrid, spheres: np.ndarray, margin: float,
                       table_z: float | None = None) -> np.ndarray:
    """(N, 3) voxel indices whose centres lie inside some true object's bounding sphere enlarged by `margin`
    (the thesis scores unknown voxels there), above the table top when `table_z` is given."""
    shape = np.array(grid.shape)
    found = []
    for c, r in zip(spheres[:, :3], spheres[:, 3] + margin):
        lo = np.clip(grid.index_of((c - r)[None])[0], 0, shape)
        hi = np.clip(grid.index_of((c + r)[None])[0] + 1, 0, shape)
        if np.any(hi <= lo):
            continue
        idx = np.stack(np.meshgrid(*[np.arange(a, b) for a, b in zip(lo, hi)], indexing="ij"), -1).reshape(-1, 3)
        cen = grid.centers(idx)
        keep = np.linalg.norm(cen - c, axis=1) <= r
        if table_z is not None:
            keep &= cen[:, 2] > table_z
        found.append(np.ravel_multi_index(tuple(idx[keep].T), grid.shape))
    if not found:
        return np.zeros((0, 3), np.int64)
    return np.stack(np.unravel_index(np.unique(np.concatenate(found)), grid.shape), -1)


def run_exploration(sc: SimScene, cfg: LoopConfig, quiet: bool = True, scene_name: str | None = None,
                    log=None, map_trials: TrialMap | None = None, load=None) -> dict:
    """POI-free whole-scene exploration (thesis ch. 3, Table 3.1 / Fig. 3.17): from a short initial scan
    (the first `scan_frames` scan poses, one side of the table) each strategy of `cfg.strategies` takes up to
    `views` NBVs, each rendered with the simulated Kinect and fused as in the POI loop. ``objects``: contour
    viewpoints of the most salient segment scored on its bounding sphere + 0.2 m (thesis Alg. 4);
    ``standard``: every contour viewpoint scored on the whole volume. Both skip views already taken (within
    `exclude_shift` m and `exclude_turn_deg`), score with the same ray caster on a `score_width`-wide image
    of the sensor's field of view and ranges, and stop when the best score < `score_fraction` of its pixels.
    Measured after each view: unknown voxels inside the true objects' bounding spheres + `near_margin`.
    map_trials: run the strategies through this map (a Dask cluster; `load` rebuilds `sc` in a worker, a
    picklable callable) instead of one after the other here."""
    if sc.object_spheres is None or len(sc.object_spheres) == 0:
        raise ConfigError(f"{scene_name or sc.name}: the objects and standard strategies need the true objects of "
                          "a kinfu synth ground_truth folder (objects/*.ply); a bare mesh has none",
                          parameter="strategies")
    timer = _Timer()
    t0 = time.perf_counter()
    sensor, K, cam = _sensor_setup(sc, cfg)
    s = min(1.0, cfg.score_width / cam.width)
    sw, sh = max(int(round(cam.width * s)), 8), max(int(round(cam.height * s)), 6)
    Ks = _scaled_K(K, cam.width, cam.height, sw, sh)
    score_cam = CameraModel(Ks[0, 0], Ks[1, 1], Ks[0, 2], Ks[1, 2], sw, sh, min_range=cam.min_range, max_range=cam.max_range,
                            vfov_extra_deg=cam.vfov_extra_deg)
    score_th = cfg.score_fraction * score_cam.width * score_cam.height
    t = time.perf_counter()
    scan = sc.scan_poses[:cfg.scan_frames]
    base, n_int = _initial_scan(sc, cfg, sensor, K, scan, sc.render_after, scene_name or sc.name, quiet)
    timer.add("initial_scan", time.perf_counter() - t)
    grid0 = base.ternary_grid()
    near = near_object_voxels(grid0, sc.object_spheres, cfg.near_margin, sc.table_z)
    near_t = tuple(near.T)
    u0 = _unknown_near(base, near_t)
    env_c = grid0.origin + np.array(grid0.shape) * grid0.voxel_size / 2
    env_r = float(np.linalg.norm(np.array(grid0.shape) * grid0.voxel_size) / 2)
    if map_trials is not None and load is None:
        raise ValueError("run_exploration: map_trials needs `load`, the scene's picklable loader")
    trials = LoopTrials(cfg, base, load, scene=(sc, sensor, K, cam), quiet=quiet,
                        extra=dict(near_t=near_t, u0=u0, env_c=env_c, env_r=env_r, score_cam=score_cam,
                                   score_th=score_th, start=scan[-1]))
    runs = {}
    for strat, (run, times) in zip(cfg.strategies, (map_trials or serial_trials)(_explore_trial, cfg.strategies,
                                                                                 trials)):
        runs[strat] = run
        for k, v in times.items():
            timer.add(k, v)
        if log is not None:
            log(strat, run)
    doc = {"scene": scene_name or sc.name, "kind": "exploration", "config": _cfg_doc(cfg),
           "camera": cam.to_dict(), "score_camera": score_cam.to_dict(), "score_threshold": score_th,
           "volume": {"shape": list(base.shape), "voxel_size": base.voxel_size, "origin": base.origin.tolist()},
           "initial_scan_views": int(n_int),
           "near_objects": {"spheres": sc.object_spheres.tolist(), "margin_m": cfg.near_margin,
                            "voxels": int(len(near)), "unknown_initial": u0},
           "strategies": runs}
    doc.update(compare_exploration(runs))
    doc["time_s"] = {k: round(v, 3) for k, v in timer.t.items()}
    doc["time_s"]["total"] = round(time.perf_counter() - t0, 3)
    return doc


def _unknown_near(vol, near_t: tuple) -> int:
    """Unknown voxels near the objects as the planners see them: observed fewer than W_th times."""
    return int(np.sum(known_grid(vol)[0].labels[near_t] == 0))


def _explore_trial(trials: LoopTrials, strat: str) -> tuple[dict, dict]:
    """One exploration strategy (objects or standard) from a copy of the initial scan -> (result, timings)."""
    sc, sensor, K, _ = trials.setup()
    cfg, x, timer = trials.cfg, trials.extra, _Timer()
    vol = trials.base.copy()
    T_cur = np.array(x["start"], dtype=float)
    taken: list[np.ndarray] = []
    curve, cast, secs, scores, segs, frames = [x["u0"]], [], [], [], [], 0
    for _ in progress(range(cfg.views), total=cfg.views, desc=strat, quiet=trials.quiet):
        t = time.perf_counter()
        weights = vol.weights()  # one extraction for the score and the contours
        grid, _ = known_grid(vol, weights=weights)
        scorer = nbv_scorer(grid, x["score_cam"], cfg.gain, table_z=sc.table_z, reject_unknown=cfg.reject_unknown,
                            optimistic=cfg.optimistic)
        contours, _ = volume_contours(vol, weights=weights)
        ex = dict(exclude=np.array(taken).reshape(-1, 4, 4), exclude_shift=cfg.exclude_shift,
                  exclude_turn_deg=cfg.exclude_turn_deg, score_threshold=x["score_th"])
        if strat == "objects":
            plan = plan_object_views(analyse_volume(vol, SegmentOptions(superquadrics=False)), contours, scorer, **ex)
        else:
            plan = plan_standard_views(contours, scorer, x["env_c"], x["env_r"], **ex)
        secs.append(time.perf_counter() - t)
        timer.add("plan", secs[-1])
        cast.append(int(plan.candidates_evaluated))
        if plan.pose is None:
            break
        scores.append(float(plan.score))
        segs.append(plan.segment_id)
        frames = _take_view(vol, T_cur, plan.pose, "kfovp", sc, cfg, sensor, K, timer, frames,
                            cfg.explore_view_frames)
        T_cur = plan.pose
        taken.append(plan.pose)
        t = time.perf_counter()
        curve.append(_unknown_near(vol, x["near_t"]))
        timer.add("measure", time.perf_counter() - t)
    run = {"strategy": strat, "unknown_near": curve, "candidates_cast": cast,
           "candidates_cast_total": int(sum(cast)), "planning_seconds": [round(v, 3) for v in secs],
           "planning_seconds_total": round(float(sum(secs)), 3), "scores": scores,
           "segments": segs, "views_taken": len(curve) - 1, "frames_fused": frames,
           "poses": [T.tolist() for T in taken]}
    return run, timer.t


def compare_exploration(runs: dict) -> dict:
    """Object-driven vs standard (thesis Table 3.1): candidate views ray-cast by each to reach the SAME
    unknown-voxel count near objects -- the level both reached (the larger of the two final counts), each
    strategy's cost counted up to its first view at or below it -- plus totals over all views."""
    if "objects" not in runs or "standard" not in runs:
        return {}
    o, st = runs["objects"], runs["standard"]
    target = max(o["unknown_near"][-1], st["unknown_near"][-1])

    def reach(r):
        k = next((i for i, u in enumerate(r["unknown_near"]) if u <= target), 0)
        return k, int(sum(r["candidates_cast"][:k])), float(sum(r["planning_seconds"][:k]))

    (ko, co, so), (ks, cs, ss) = reach(o), reach(st)
    u0 = o["unknown_near"][0]
    out = {"equal_reduction": {
        "unknown_near": int(target), "reduction": int(u0 - target),
        "reduction_fraction": (u0 - target) / u0 if u0 else 0.0,
        "objects_views": ko, "objects_cast": co, "objects_planning_s": round(so, 3),
        "standard_views": ks, "standard_cast": cs, "standard_planning_s": round(ss, 3),
        "cast_ratio": cs / co if co else None, "time_ratio": ss / so if so > 0 else None}}
    out["reduction"] = {name: int(r["unknown_near"][0] - r["unknown_near"][-1]) for name, r in runs.items()}
    out["cast_ratio_standard_over_objects"] = st["candidates_cast_total"] / max(o["candidates_cast_total"], 1)
    out["time_ratio_standard_over_objects"] = st["planning_seconds_total"] / max(o["planning_seconds_total"], 1e-9)
    return out


def _run_strategy(strat, mode, vol, pois, sc, cfg, sensor, K, cam, sphere, table_z, timer) -> dict:
    """One strategy in one mode from the cleared volume `vol` (modified in place)."""
    rng = np.random.default_rng(cfg.seed + 1)
    T_cur = sc.scan_poses[-1].copy()
    unknown: dict[int, list[int]] = {}
    gains: dict[int, list[float]] = {}
    until: dict[int, int | None] = {}
    taken: dict[int, int] = {}
    frames = 0
    per_view_s = []
    for pid, p in enumerate(pois):
        cands = sphere_viewpoints(p, **sphere)
        attempted: set[int] = set()
        fixed = _fixed_ring(cands, p, cfg.views) if strat == "fixed" else []
        grid = vol.ternary_grid()
        unknown[pid] = [unknown_in_sphere(grid, p, cfg.poi_radius)]
        gains[pid] = []
        until[pid] = None
        th = cfg.inc_th
        for step in range(cfg.views):
            tv = time.perf_counter()
            t = time.perf_counter()
            s = score_views(grid, cands, cam, p, cfg.poi_radius, cfg.gain, table_z=table_z,
                            reject_unknown=cfg.reject_unknown, optimistic=cfg.optimistic)
            if th is None:
                th = default_inc_th(s)
            order = [int(i) for i in s.order() if int(i) not in attempted]
            best_gain = float(s.gain[order[0]]) if order else 0.0
            timer.add("rank", time.perf_counter() - t)
            gains[pid].append(best_gain)
            if best_gain < th and until[pid] is None:
                until[pid] = step
            if strat == "poi":
                if best_gain < th or not order:
                    break
                pick = order[0]
            elif strat == "random":
                valid = [i for i in np.flatnonzero(s.valid) if int(i) not in attempted]
                if not valid:
                    break
                pick = int(rng.choice(valid))
            else:
                if step >= len(fixed):
                    break
                pick = fixed[step]
            # a view is attempted with all its rolls (rolls only matter for the robot's IK)
            T_goal = cands[pick]
            same = np.linalg.norm(cands[:, :3, 3] - T_goal[:3, 3], axis=1) < 1e-6
            attempted.update(int(i) for i in np.flatnonzero(same))
            frames = _take_view(vol, T_cur, T_goal, mode, sc, cfg, sensor, K, timer, frames)
            T_cur = T_goal
            t = time.perf_counter()
            grid = vol.ternary_grid()
            unknown[pid].append(unknown_in_sphere(grid, p, cfg.poi_radius))
            timer.add("measure", time.perf_counter() - t)
            per_view_s.append(time.perf_counter() - tv)
        taken[pid] = len(unknown[pid]) - 1
        if until[pid] is None:  # IncTh after the last view?
            s = score_views(grid, cands, cam, p, cfg.poi_radius, cfg.gain, table_z=table_z,
                            reject_unknown=cfg.reject_unknown, optimistic=cfg.optimistic)
            o = [int(i) for i in s.order() if int(i) not in attempted]
            if (float(s.gain[o[0]]) if o else 0.0) < th:
                until[pid] = taken[pid]
    t = time.perf_counter()
    err = reconstruction_error(vol, sc.after, pois, cfg.poi_radius, cfg.threshold)
    timer.add("error", time.perf_counter() - t)
    return {"strategy": strat, "mode": mode, "unknown": {str(k): v for k, v in unknown.items()},
            "best_gain": {str(k): v for k, v in gains.items()},
            "views_taken": {str(k): v for k, v in taken.items()},
            "views_until_incth": {str(k): v for k, v in until.items()},
            "inc_th": th, "frames_fused": frames,
            "final_unknown": int(sum(v[-1] for v in unknown.values())),
            "initial_unknown": int(sum(v[0] for v in unknown.values())),
            "seconds_per_view": round(float(np.mean(per_view_s)), 3) if per_view_s else 0.0,
            "error": err}


def reconstruction_error(vol, true_mesh, pois: np.ndarray, radius: float, threshold: float) -> dict:
    """Accuracy and completeness of the fused surface inside the POI spheres vs the true mesh."""
    tv = np.asarray(true_mesh.vertices, dtype=np.float64)
    tt = np.asarray(true_mesh.triangles, dtype=np.int64)
    rec = vol.extract_mesh()
    rv = np.asarray(rec.vertices, dtype=np.float64)
    rt = np.asarray(rec.triangles, dtype=np.int64)

    def in_spheres(x):
        if len(x) == 0:
            return np.zeros(0, bool)
        return np.min(np.linalg.norm(x[:, None, :] - pois[None], axis=2), axis=1) < radius

    out: dict = {"threshold_m": threshold}
    sel = rv[in_spheres(rv)] if len(rv) else rv
    if len(sel):
        d = point_to_mesh_distance(sel, tv, tt)
        out.update(accuracy_mean_m=float(np.mean(d)), accuracy_median_m=float(np.median(d)),
                   precision=float(np.mean(d < threshold)), vertices=int(len(sel)))
    else:
        out.update(accuracy_mean_m=None, accuracy_median_m=None, precision=None, vertices=0)
    samples = _sample_surface(true_mesh, pois, radius)
    samples = samples[in_spheres(samples)]
    if len(samples) and len(rt):
        d = point_to_mesh_distance(samples, rv, rt)
        out.update(completeness=float(np.mean(d < threshold)), true_samples=int(len(samples)))
    else:
        out.update(completeness=0.0 if len(samples) else None, true_samples=int(len(samples)))
    return out


def _sample_surface(mesh: o3d.geometry.TriangleMesh, pois: np.ndarray, radius: float, spacing: float = 0.004
                    ) -> np.ndarray:
    """Area-uniform samples (about one per spacing^2, at most 400,000) of the triangles near the POI spheres."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles, dtype=np.int64)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    cen = (a + b + c) / 3
    reach = np.max(np.linalg.norm(np.stack([a, b, c]) - cen, axis=2), axis=0)
    near = t[np.min(np.linalg.norm(cen[:, None, :] - pois[None], axis=2), axis=1) < radius + reach]
    count = min(int(surface_area(v, near) / spacing ** 2) + 1, 400_000)
    return sample_triangles(v, near, count, seed=0)[0]


def compare_strategies(seed: int = 0, *, views: int = 5, scan_frames: int = 8, score_px: int = 80,
                       voxel_size: float = 0.01, width: int | None = 160, height: int | None = 120,
                       strategies=("objects", "standard"), log=None, quiet: bool = True, **config) -> dict:
    """Thesis Fig. 3.17 / Table 3.1 in simulation on `make_scenario(seed)` (no files): from a short one-sided
    scan (`scan_frames` poses), take `views` NBVs with each strategy, counting unknown voxels inside the true
    objects' bounding spheres + 0.2 m after each view, candidate views ray-cast and planning time. Views are
    scored on a `score_px`-wide image of the sensor's field of view. Extra keyword arguments are `LoopConfig`
    fields. Returns the `run_exploration` document."""
    cfg = LoopConfig(strategies=tuple(strategies), views=views, scan_frames=scan_frames, score_width=score_px,
                     voxel_size=voxel_size, width=width, height=height, seed=seed, **config)
    cfg.check()
    return run_exploration(scene_from_scenario(seed), cfg, quiet=quiet, scene_name=f"scenario seed {seed}", log=log)
