"""Which way is up in a fused volume's world frame: given, declared, REP-103, or estimated from the data.

`choose_up` decides once per fusion run, first rule that applies:
1. "option": the caller gives the direction.
2. "init": the volume being continued has one (kept).
3. "recording": the recording declares it for the frame of the camera poses (io.world_up; written by
   `kinfu import` when given an up direction).
4. "tf-rep103": the camera poses are in a TF (or pose topic) frame named as a REP-103 / REP-105 fixed frame
   (world, map, odom, earth, base_link, base_footprint; a namespace prefix allowed), whose z axis points up,
   and the recording does not declare otherwise (imported frame folders do: their `world` is the data set's
   frame). The data estimate below is still made; when it finds a plane further than REP103_DISAGREE_DEG
   from z, a warning says so (the up stays z: the name is the recording's own statement). A declared up
   (rule 3) is checked against the estimate the same way.
5. "estimated-plane" / "camera": `estimate_up` from the fused surface and the camera poses.
6. "unknown" (None) when nothing says anything.

`estimate_up`: cameras are mostly held upright, so the mean of the cameras' image-up axes (-y of the optical
frame, in world coordinates) leans towards up; it is off by the cameras' mean downward tilt (a camera looking
down at 60 deg has its image-up 60 deg from up), less when the trajectory goes round the scene (the tilts
cancel). The support surface (floor, table top) is a large plane that the cameras look at from above. So:
RANSAC planes of the surface cloud (largest first, PLANE_ROUNDS of them; inliers are near the plane with a
surface normal along it), each oriented towards the side
where most cameras are; a plane qualifies when it holds PLANE_MIN_FRACTION of the surface, at least
CAMERAS_ABOVE_MIN of the cameras are on its upper side, and its normal is within MAX_ANGLE_TO_CAMERA_UP_DEG of
the camera up (walls facing the cameras point against it, side walls across it). Of the qualifying planes
the one with the most inliers times cos(angle to the camera up) wins and its normal is up
("estimated-plane"). Without one, the camera up itself ("camera", with a warning: it is off by the tilt);
when the cameras' image-up axes cancel out (resultant below CAMERA_UP_MIN_RESULTANT) they say nothing and
only a plane below the cameras can decide.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.core.neighbours import grid_cells

# fixed frames that REP-103 / REP-105 make z-up (ENU); the last path component counts ("robot1/map")
REP103_FRAMES = ("world", "map", "odom", "earth", "base_link", "base_footprint")
# surface points are thinned to this spacing (m) before the plane search: support planes are metres wide
SURFACE_SPACING = 0.02
# RANSAC inlier distance (m): fused real surfaces bend by about a centimetre (drift, depth noise)
PLANE_DISTANCE = 0.02
# an inlier's surface normal is within this of the plane's: points of walls and box sides crossing a thick
# plane would otherwise tilt its least-squares normal
PLANE_NORMAL_TOLERANCE_DEG = 25.0
PLANE_ITERATIONS = 400  # RANSAC hypotheses per plane: >99.9 % to hit a 10 % plane (3 points inside)
PLANE_ROUNDS = 6  # planes tried, largest first (floor, table, walls, box faces)
PLANE_MIN_FRACTION = 0.05  # a support plane holds at least this share of the surface
CAMERAS_ABOVE_MIN = 0.8  # share of the cameras that must be on the upper side of a support plane
# a support plane's normal is within this of the cameras' mean image-up: cameras looking down by up to
# 75 deg still have their image-up within 75 deg of up
MAX_ANGLE_TO_CAMERA_UP_DEG = 75.0
# below this resultant length the cameras' image-up axes point every way (rolled cameras): no evidence
CAMERA_UP_MIN_RESULTANT = 0.3
# a plane this far from z in a REP-103 frame is worth a warning (walls are 90 deg away, tilts are small)
REP103_DISAGREE_DEG = 45.0
SEED = 0  # RANSAC samples: one answer per input


@dataclass
class UpChoice:
    """The up direction of a run (unit (3,) or None), where it came from, the evidence and any warnings."""

    up: np.ndarray | None
    source: str  # option, init, recording, tf-rep103, estimated-plane, camera or unknown
    evidence: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        return {"up": None if self.up is None else [round(float(v), 6) for v in self.up], "source": self.source,
                **self.evidence}


def is_rep103_frame(frame: str) -> bool:
    """True for a world frame named as a REP-103 / REP-105 fixed frame (z up), namespace prefix allowed."""
    name = (frame or "").strip("/").split("/")[-1].lower()
    return name in REP103_FRAMES


def camera_up(poses: np.ndarray) -> tuple[np.ndarray | None, float]:
    """(unit mean of the cameras' image-up axes (-y of the optical frame) in world coordinates, or None when
    they cancel out; the resultant length 0..1: 1 when every camera has the same image-up)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    if len(poses) == 0:
        return None, 0.0
    m = -poses[:, :3, 1].mean(axis=0)
    r = float(np.linalg.norm(m))
    return (m / r if r > 1e-9 else None), r


def _thin(points: np.ndarray, normals: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """One point (and its normal) per `spacing` cube (the first); finite points with unit normals only."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    length = np.linalg.norm(nrm, axis=1)
    ok = np.all(np.isfinite(p), axis=1) & np.isfinite(length) & (length > 1e-9)
    p, nrm = p[ok], nrm[ok] / length[ok, None]
    if len(p) == 0:
        return p, nrm
    first = np.sort(grid_cells(p, spacing)[0])
    return p[first], nrm[first]


def _inliers(points: np.ndarray, normals: np.ndarray, nrm: np.ndarray, d) -> np.ndarray:
    """Inlier mask(s) of plane(s) n.x + d = 0: near the plane, surface normal along the plane's (either sign).
    nrm (3,) and d scalar give (N,); nrm (K, 3) and d (K,) give (N, K)."""
    cos_tol = np.cos(np.radians(PLANE_NORMAL_TOLERANCE_DEG))
    return (np.abs(points @ nrm.T + d) <= PLANE_DISTANCE) & (np.abs(normals @ nrm.T) >= cos_tol)


def _ransac_plane(points: np.ndarray, normals: np.ndarray, rng: np.random.Generator
                  ) -> tuple[np.ndarray, float, np.ndarray] | None:
    """(unit normal, offset d with n.x + d = 0, inlier mask) of the plane with most inliers (`_inliers`)
    among PLANE_ITERATIONS random triples, refined by a least-squares fit to its inliers; None for fewer
    than 3 points."""
    n = len(points)
    if n < 3:
        return None
    best_count, best = -1, None
    for start in range(0, PLANE_ITERATIONS, 100):  # batches keep the (points x hypotheses) arrays small
        k = min(100, PLANE_ITERATIONS - start)
        tri = points[rng.integers(0, n, size=(k, 3))]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(nrm, axis=1)
        ok = length > 1e-12
        if not ok.any():
            continue
        nrm = nrm[ok] / length[ok, None]
        d = -np.einsum("ij,ij->i", nrm, tri[ok, 0])
        counts = np.count_nonzero(_inliers(points, normals, nrm, d), axis=0)
        i = int(np.argmax(counts))
        if counts[i] > best_count:
            best_count, best = int(counts[i]), (nrm[i], float(d[i]))
    if best is None:
        return None
    nrm, d = best
    inl = _inliers(points, normals, nrm, d)
    if inl.sum() >= 3:  # least squares: the normal is the direction of least spread of the inliers
        c = points[inl].mean(axis=0)
        refined = np.linalg.svd(points[inl] - c, full_matrices=False)[2][2]
        if refined @ nrm < 0:
            refined = -refined
        nrm, d = refined, -float(refined @ c)
    return np.asarray(nrm, dtype=np.float64), d, inl


def estimate_up(points: np.ndarray, normals: np.ndarray, camera_poses: np.ndarray
                ) -> tuple[np.ndarray | None, str, dict]:
    """(up or None, source "estimated-plane" / "camera" / "unknown", evidence) from surface points (N, 3)
    with their normals (N, 3; either sign) and the camera-to-world poses (F, 4, 4) of the frames fused.
    See the module docstring."""
    poses = np.asarray(camera_poses, dtype=np.float64).reshape(-1, 4, 4)
    cam_up, resultant = camera_up(poses)
    informative = cam_up is not None and resultant >= CAMERA_UP_MIN_RESULTANT
    centres = poses[:, :3, 3]
    pts, nrms = _thin(points, normals, SURFACE_SPACING)
    evidence: dict = {"camera_up": None if cam_up is None else np.round(cam_up, 4).tolist(),
                      "camera_up_resultant": round(resultant, 3), "surface_points": int(len(pts)), "planes": []}
    rng = np.random.default_rng(SEED)
    remaining, remaining_n = pts, nrms
    best = None
    cos_max = np.cos(np.radians(MAX_ANGLE_TO_CAMERA_UP_DEG))
    for _ in range(PLANE_ROUNDS):
        if len(pts) == 0 or len(remaining) < PLANE_MIN_FRACTION * len(pts):
            break
        found = _ransac_plane(remaining, remaining_n, rng)
        if found is None:
            break
        nrm, d, inl = found
        side = centres @ nrm + d
        if np.mean(side > 0) < 0.5:  # orient towards the cameras
            nrm, d, side = -nrm, -d, -side
        fraction = float(inl.sum()) / len(pts)
        above = float(np.mean(side > 0))
        cos_cam = float(nrm @ cam_up) if informative else 1.0
        plane = {"normal": np.round(nrm, 4).tolist(), "points_fraction": round(fraction, 3),
                 "cameras_above": round(above, 3),
                 "angle_to_camera_up_deg": (round(float(np.degrees(np.arccos(np.clip(cos_cam, -1, 1)))), 1)
                                            if informative else None)}
        qualifies = fraction >= PLANE_MIN_FRACTION and above >= CAMERAS_ABOVE_MIN and cos_cam >= cos_max
        plane["qualifies"] = bool(qualifies)
        evidence["planes"].append(plane)
        if qualifies and (best is None or fraction * cos_cam > best[0]):
            best = (fraction * cos_cam, nrm, plane)
        remaining, remaining_n = remaining[~inl], remaining_n[~inl]
    if best is not None:
        evidence["plane"] = best[2]
        return best[1], "estimated-plane", evidence
    if informative:
        return cam_up, "camera", evidence
    return None, "unknown", evidence


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(float(a @ b), -1.0, 1.0))))


def choose_up(*, option=None, init_up=None, init_source: str = "", declared=None, world: str = "",
              world_from_tf: bool = False, points: np.ndarray | None = None, normals: np.ndarray | None = None,
              camera_poses: np.ndarray | None = None, up_name: str = "up") -> UpChoice:
    """The up direction of a fusion run (see the module docstring for the order of the rules).

    option: the caller's unit direction or None; init_up / init_source: those of a continued volume;
    declared: io.world_up.WorldUp of the recording or None; world: the frame of the camera poses and
    world_from_tf whether it is a TF / pose-topic frame (not ICP's first camera); points, normals: surface
    points of the fused volume and their normals; camera_poses: the poses of the fused frames; up_name:
    how warnings name the option.
    """
    if option is not None:
        return UpChoice(np.asarray(option, dtype=np.float64), "option")
    if init_up is not None:
        return UpChoice(np.asarray(init_up, dtype=np.float64), init_source or "init", {"kept_from": "init"})
    if declared is not None and declared.frame != world:
        declared = None  # a declaration about another frame (the poses are in the first camera's, say)
    pts = np.zeros((0, 3)) if points is None else points
    nrms = np.zeros((0, 3)) if normals is None else normals
    poses = np.zeros((0, 4, 4)) if camera_poses is None else camera_poses
    est, source, evidence = estimate_up(pts, nrms, poses)
    if declared is not None and declared.up is not None:
        choice = UpChoice(declared.up, "recording", {"declared_frame": declared.frame, "estimate": {
            "up": None if est is None else np.round(est, 4).tolist(), "source": source}})
        if source == "estimated-plane" and _angle_deg(est, declared.up) > REP103_DISAGREE_DEG:
            choice.warnings.append(
                f"the recording declares up {np.round(declared.up, 3).tolist()} for {declared.frame!r}, but the "
                f"largest plane below the cameras points along {np.round(est, 3).tolist()}, "
                f"{_angle_deg(est, declared.up):.0f} deg away; keeping the declared up (give {up_name} if the "
                f"declaration is wrong, e.g. y-up given for a y-down frame)")
        return choice
    if declared is None and world_from_tf and is_rep103_frame(world):
        z = np.array([0.0, 0.0, 1.0])
        choice = UpChoice(z, "tf-rep103", {"world_frame": world, "estimate": {"up": None if est is None else
                                                                                np.round(est, 4).tolist(),
                                                                                "source": source}})
        if source == "estimated-plane" and _angle_deg(est, z) > REP103_DISAGREE_DEG:
            choice.warnings.append(
                f"the world frame {world!r} is a REP-103 frame (z up), but the largest plane below the cameras "
                f"points along {np.round(est, 3).tolist()}, {_angle_deg(est, z):.0f} deg from z; keeping z up "
                f"(give {up_name} if this recording does not follow REP-103)")
        return choice
    choice = UpChoice(est, source, evidence)
    why = (f"the world frame {world!r} is not known to be z-up" if world else
           "the world frame is the first camera")
    if declared is not None:
        why = f"the recording declares its world frame {declared.frame!r} without an up direction"
    if source == "camera":
        choice.warnings.append(
            f"{why} and no large plane lies below the cameras: up is the cameras' mean image-up "
            f"{np.round(est, 3).tolist()}, which is off by their downward tilt (give {up_name})")
    elif source == "unknown":
        choice.warnings.append(f"{why} and neither a plane below the cameras nor their orientation tells which "
                               f"way is up: segment and nbv will assume z (give {up_name})")
    return choice


# plots name world axes when up is this close to one (a y-down world's -y, not an oblique "up")
AXIS_SNAP_DEG = 5.0


@dataclass(frozen=True)
class ViewAxes:
    """Right-handed plot axes for a world with an up direction: top views show (e1, e2), side views (e1, up).

    axis: index of the world axis up runs along (its sign in `sign`) when up is within AXIS_SNAP_DEG of
    one, else None; e1_axis / e2_axis: the world axes e1, e2 are then (positive ones; None otherwise).
    z up gives (x, y, z), y down (x, z, -y).
    """

    e1: np.ndarray
    e2: np.ndarray
    up: np.ndarray
    names: tuple[str, str, str]
    axis: int | None
    sign: float
    e1_axis: int | None
    e2_axis: int | None


def view_axes(up=None) -> ViewAxes:
    """The plot axes of `up` (None: z up, the plots' old convention)."""
    u = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    a = int(np.argmax(np.abs(u)))
    if abs(u[a]) >= np.cos(np.radians(AXIS_SNAP_DEG)):
        s = float(np.sign(u[a]))
        b, c = (a + 1) % 3, (a + 2) % 3  # e_b x e_c = e_a, e_c x e_b = -e_a: right-handed with up = s e_a
        i1, i2 = (b, c) if s > 0 else (c, b)
        eye = np.eye(3)
        return ViewAxes(eye[i1], eye[i2], s * eye[a], ("xyz"[i1], "xyz"[i2], ("" if s > 0 else "-") + "xyz"[a]),
                        a, s, i1, i2)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ u) * u
    e1 /= np.linalg.norm(e1)
    return ViewAxes(e1, np.cross(u, e1), u, ("horizontal 1", "horizontal 2", "up"), None, 1.0, None, None)


def z_to_up_rotation(up=None) -> np.ndarray:
    """The smallest rotation (3x3) taking z (0, 0, 1) to `up` (identity for None or z; 180 deg about x for -z):
    what turns the z-up constructions (the NBV viewing sphere) into the world's."""
    if up is None:
        return np.eye(3)
    u = np.asarray(up, dtype=np.float64).reshape(3)
    u = u / np.linalg.norm(u)
    v = np.cross([0.0, 0.0, 1.0], u)
    s, c = float(np.linalg.norm(v)), float(u[2])
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx * ((1.0 - c) / (s * s))
