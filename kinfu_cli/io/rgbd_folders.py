"""RGB-D frame folders (7-Scenes / 3DMatch layout, TUM RGB-D layout) and their conversion into recordings.

Layouts
- 7-Scenes / 3DMatch: `frame-N.depth.png` (uint16 mm; 0 and 65535 = no measurement), `frame-N.color.png|jpg`,
  `frame-N.pose.txt` (4x4 camera-to-world, metres), `camera-intrinsics.txt` or `intrinsics.K.txt` (3x3 K).
  No stamps: frame N is at t = N / rate seconds (rate 30 Hz unless told).
- TUM RGB-D: `depth.txt`, `rgb.txt` ("stamp path" lines), `groundtruth.txt` ("stamp tx ty tz qx qy qz qw",
  camera-to-world). Depth PNGs hold 5000 units per metre; they are converted to millimetres (0.2 mm
  rounding). K from an intrinsics file in the folder, the `intrinsics` argument, or the TUM camera named in
  the folder name (freiburg1/2/3), else the TUM default 525/525/319.5/239.5 (with a warning); the last two are
  for 640x480 images only (other sizes need the intrinsics).

Recordings written by `import_folder` (names documented for users and tests):
- `/camera/depth/image_raw` sensor_msgs/Image 16UC1 (mm), frame `camera_optical`
- `/camera/depth/camera_info` sensor_msgs/CameraInfo (K, image size), frame `camera_optical`
- `/camera/color/image_raw/compressed` sensor_msgs/CompressedImage with the data set's own jpeg/png bytes
  (or `/camera/color/image_raw` rgb8 with color="raw"), frame `camera_optical` (colour of these data sets is
  not registered to the depth camera: use it for texture only)
- `/tf`: `world -> camera_optical` (T_world_camera), at each depth stamp (7-Scenes) or each ground-truth
  sample around the frames (TUM). Rotations are projected onto the nearest rotation matrix (SVD): 7-Scenes
  poses are orthonormal only to ~1e-4. A 7-Scenes frame without a usable pose (no pose file, -inf/NaN) among
  posed frames is left out, with a warning: fusion would interpolate a pose for it from its neighbours.
- `/kinfu/world_up` geometry_msgs/Vector3Stamped (io.world_up), once at the first stamp, frame `world`: the
  `up` direction given to the import, else the zero vector. `world` here is the data set's frame (7-Scenes: a
  KinectFusion volume frame, TUM: the motion-capture frame, a 3DMatch or tabletop folder: often the first
  camera), not a REP-103 z-up frame, and this message keeps fusion from taking it for one.
"""

from __future__ import annotations

import json
import math
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from kinfu_cli.core.atomic import atomic_dir
from kinfu_cli.core.camera import SENSOR_PRESETS, parse_intrinsics
from kinfu_cli.core.errors import ConfigError, RecordingError
from kinfu_cli.core.grid import check_up
from kinfu_cli.core.poses import quaternion_to_matrix
from kinfu_cli.core.progress import progress
from kinfu_cli.io.frames import FrameStats, iter_frames
from kinfu_cli.io.messages import imread_quiet
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.roles import detect_roles
from kinfu_cli.io.world_up import WORLD_UP_TOPIC
from kinfu_cli.io.writers import RecordingWriter, format_for

WORLD_FRAME = "world"
CAMERA_FRAME = "camera_optical"
DEPTH_TOPIC = "/camera/depth/image_raw"
INFO_TOPIC = "/camera/depth/camera_info"
COLOR_TOPIC_RAW = "/camera/color/image_raw"
COLOR_TOPIC_COMPRESSED = "/camera/color/image_raw/compressed"

_FRAME_RE = re.compile(r"^frame-(\d+)\.depth\.png$")
_INTRINSICS_FILES = ("camera-intrinsics.txt", "intrinsics.K.txt", "intrinsics.txt", "camera_intrinsics.txt")
_TUM_K = {"freiburg1": (517.3, 516.5, 318.6, 255.3), "freiburg2": (520.9, 521.0, 325.1, 249.7),
          "freiburg3": (535.4, 539.2, 320.1, 247.6)}
_TUM_DEFAULT_K = tuple(SENSOR_PRESETS["kinect_v1"][k] for k in ("fx", "fy", "cx", "cy"))  # TUM's "ROS default"
MIN_RATE_HZ, MAX_RATE_HZ = 1e-3, 1e6
RIGID_TOLERANCE = 1e-2  # largest |R^T R - I| entry of a pose file's rotation (7-Scenes poses reach ~1e-4)
MAX_TRANSLATION_M = 1e6
# an export's frames whose K entries differ by no more than this (px) share one camera-intrinsics.txt: a camera info
# republished with float noise; a pixel's ray then moves by about as much at the image edge, far below depth noise
SAME_CAMERA_PX = 1e-3
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_JPEG_MAGIC = b"\xff\xd8\xff"


@dataclass
class FolderFrame:
    """One frame of a folder: its number, stamp, files, and pose (None when the folder has none; then
    pose_problem says why for a 7-Scenes frame: "missing" pose file or "not finite")."""

    number: int
    stamp_ns: int
    depth_path: Path
    color_path: Path | None
    T_world_camera: np.ndarray | None
    pose_problem: str | None = None


@dataclass
class RGBDFolder:
    path: Path
    layout: str  # "7scenes" or "tum"
    frames: list[FolderFrame]
    K: np.ndarray
    depth_units_per_m: float  # 1000 (mm) or 5000 (TUM)
    k_source: str
    k_assumed: bool = False  # K is a TUM calibration picked by folder name or TUM's default, not read or given
    gt_stamps_ns: np.ndarray | None = None  # TUM ground truth, all samples
    gt_poses: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def nearest_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation matrix closest to R (Frobenius norm), by SVD."""
    U, _, Vt = np.linalg.svd(R)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def _read_matrix(path: Path, shape: tuple[int, int], what: str) -> np.ndarray:
    try:
        with warnings.catch_warnings():  # an empty file: numpy warns, the size check below says it
            warnings.simplefilter("ignore")
            M = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{path}: cannot read the {what} ({exc})") from None
    if M.size != shape[0] * shape[1]:
        raise RecordingError(f"{path}: {what} has {M.size} numbers, expected a {shape[0]}x{shape[1]} matrix")
    return M.reshape(shape)


def _check_rigid(T: np.ndarray, path: Path) -> None:
    """RecordingError naming `path` unless the finite 4x4 T is a rigid camera pose (within RIGID_TOLERANCE)."""
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > RIGID_TOLERANCE or np.linalg.det(R) <= 0:
        raise RecordingError(f"{path}: pose is not a rigid transform (rotation part off orthonormal by {err:.3g}, "
                             f"det {np.linalg.det(R):.3g}; expected |R^T R - I| <= {RIGID_TOLERANCE:g}, det +1)")
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9:
        raise RecordingError(f"{path}: pose's last row is {T[3].tolist()}, expected [0, 0, 0, 1]")
    if np.abs(T[:3, 3]).max() > MAX_TRANSLATION_M:
        raise RecordingError(f"{path}: pose translation {T[:3, 3].tolist()} is beyond {MAX_TRANSLATION_M:g} m")


def _read_K(folder: Path, intrinsics: tuple[float, float, float, float] | None,
            intrinsics_source: str) -> tuple[np.ndarray | None, str]:
    """K and where it came from: the caller's intrinsics, else the intrinsics files of the folder or, when it has
    none, of its parent (3DMatch: the scene root). Files of one folder that disagree are an error."""
    if intrinsics is not None:
        fx, fy, cx, cy = intrinsics
        return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]), intrinsics_source
    for d in (folder, folder.parent):
        found = [d / name for name in _INTRINSICS_FILES if (d / name).is_file()]
        if not found:
            continue
        Ks = [_read_matrix(p, (3, 3), "intrinsics") for p in found]
        for p, K in zip(found, Ks):
            if not (np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0):
                raise RecordingError(f"{p}: intrinsics are not finite with positive focal lengths (fx={K[0, 0]}, "
                                     f"fy={K[1, 1]})")
            if not np.allclose(K, Ks[0], rtol=1e-6, atol=1e-9):
                raise RecordingError(f"{found[0]} and {p}: the intrinsics files disagree ({Ks[0].tolist()} vs "
                                     f"{K.tolist()}); expected one K: remove the wrong file")
        p = found[0]
        return Ks[0], str(p.relative_to(folder.parent)) if p.parent != folder else p.name
    return None, ""


def parse_frames(text: str | None, n: int) -> slice:
    """Frame selection text: 'N' (first N), 'A:B' or 'A:B:S' (positions in the sorted frame list)."""
    if text is None:
        return slice(None)
    try:
        parts = [int(p) if p.strip() else None for p in text.split(":")]
    except ValueError:
        parts = []
    if len(parts) == 1 and parts[0] is not None and parts[0] > 0:
        return slice(0, parts[0])
    if 2 <= len(parts) <= 3 and (len(parts) < 3 or parts[2] is None or parts[2] > 0):
        return slice(*parts)
    raise ConfigError(f"expected N (first N frames), A:B or A:B:STEP, got {text!r}", parameter="frames")


def scan_folder(path: str | os.PathLike, rate: float = 30.0,
                intrinsics: tuple[float, float, float, float] | None = None,
                intrinsics_source: str = "intrinsics argument") -> RGBDFolder:
    """Find the layout, frames, intrinsics and poses of an RGB-D folder (RecordingError when none fits).

    intrinsics_source: how `k_source` names intrinsics given here (callers name their own option).
    """
    folder = Path(path)
    if not folder.is_dir():
        raise RecordingError(f"{folder}: not a folder, expected an RGB-D frame folder (7-Scenes or TUM layout)")
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:  # also refuses NaN; stamps N / rate stay inside int64 ns
        raise ConfigError(f"expected a frame rate in [{MIN_RATE_HZ:g}, {MAX_RATE_HZ:g}] Hz, got {rate}",
                          parameter="rate")
    if (folder / "depth.txt").is_file():
        return _scan_tum(folder, intrinsics, intrinsics_source)
    depth_files = sorted((int(m.group(1)), p) for p in folder.iterdir() if (m := _FRAME_RE.match(p.name)))
    if not depth_files:
        seqs = sorted(p.name for p in folder.iterdir() if p.is_dir() and any(p.glob("frame-*.depth.png")))
        if seqs:
            raise RecordingError(f"{folder}: frames are in sequence folders ({', '.join(seqs)}); import one of "
                                 f"them, e.g. {folder / seqs[0]}")
        raise RecordingError(f"{folder}: no frame-N.depth.png files and no depth.txt, expected a 7-Scenes/3DMatch "
                             f"or TUM RGB-D folder")
    K, k_source = _read_K(folder, intrinsics, intrinsics_source)
    if K is None:
        raise RecordingError(f"{folder}: no camera-intrinsics.txt or intrinsics.K.txt (3x3 K); give the "
                             f"intrinsics fx,fy,cx,cy", parameter="intrinsics")
    frames = []
    for number, depth_path in depth_files:
        stem = depth_path.name[: -len(".depth.png")]
        color = next((folder / f"{stem}.color.{ext}" for ext in ("png", "jpg", "jpeg")
                      if (folder / f"{stem}.color.{ext}").is_file()), None)
        pose_path = folder / f"{stem}.pose.txt"
        T, problem = None, "missing"
        if pose_path.is_file():
            T, problem = _read_matrix(pose_path, (4, 4), "pose"), None
            if not np.all(np.isfinite(T)):  # 7-Scenes / 3DMatch mark frames without a pose with -inf
                T, problem = None, "not finite"
            else:
                _check_rigid(T, pose_path)
        frames.append(FolderFrame(number, int(round(number / rate * 1e9)), depth_path, color, T, problem))
    return RGBDFolder(folder, "7scenes", frames, K, 1000.0, k_source)


def _read_list(path: Path, ncols: int) -> list[list[str]]:
    rows = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) < ncols:
            raise RecordingError(f"{path}:{i}: expected {ncols} columns, got {len(parts)}")
        rows.append(parts)
    return rows


def _stamp_ns(text: str, where: str) -> int:
    """Seconds as written ("1305031102.175304") -> int ns, exactly; RecordingError naming `where` unless it is a
    non-negative decimal number of seconds that fits a ROS stamp."""
    sec, _, frac = text.partition(".")
    if not (sec.isdigit() and (frac.isdigit() or not frac)) or len(sec) > 10:
        raise RecordingError(f"{where}: timestamp {text!r} is not a number of seconds in [0, 1e10)")
    return int(sec) * 1_000_000_000 + int((frac + "000000000")[:9])


def _gt_problem(v: np.ndarray) -> str | None:
    """What is wrong with one ground-truth sample tx ty tz qx qy qz qw (None when nothing)."""
    if not np.all(np.isfinite(v)):
        return "not finite"
    if np.abs(v[:3]).max() > MAX_TRANSLATION_M:
        return f"translation beyond {MAX_TRANSLATION_M:g} m"
    n2 = float(np.dot(v[3:7], v[3:7]))
    if abs(n2 - 1.0) >= 0.01:  # tf2's tolerance on |q|^2
        return f"quaternion of length {math.sqrt(n2):.4g}"
    return None


def _scan_tum(folder: Path, intrinsics, intrinsics_source: str) -> RGBDFolder:
    depth_rows = _read_list(folder / "depth.txt", 2)
    if not depth_rows:
        raise RecordingError(f"{folder / 'depth.txt'}: no frames listed")
    rgb = []
    if (folder / "rgb.txt").is_file():
        rgb = [(_stamp_ns(r[0], str(folder / "rgb.txt")), folder / r[1]) for r in _read_list(folder / "rgb.txt", 2)]
    rgb_st = np.array([s for s, _ in rgb], dtype=np.int64)
    gt_st = gt_T = None
    folder_warnings = []
    gt_path = folder / "groundtruth.txt"
    rows = _read_list(gt_path, 8) if gt_path.is_file() else []
    if gt_path.is_file() and not rows:  # as without the file: no poses, but a file that says nothing is doubtful
        folder_warnings.append(f"{gt_path}: no 'stamp tx ty tz qx qy qz qw' sample (empty or only comments); "
                               f"the recording has no camera poses")
    if rows:
        try:
            vals = np.array([[float(v) for v in r[1:8]] for r in rows], dtype=np.float64)
        except ValueError:
            raise RecordingError(f"{gt_path}: expected 'stamp tx ty tz qx qy qz qw' numbers") from None
        for i, v in enumerate(vals):
            why = _gt_problem(v)
            if why:
                raise RecordingError(f"{gt_path}: sample {i + 1} ({rows[i][0]}): {why}; expected "
                                     f"'stamp tx ty tz qx qy qz qw' with a unit quaternion")
        gt_st = np.array([_stamp_ns(r[0], str(gt_path)) for r in rows], dtype=np.int64)
        order = np.argsort(gt_st, kind="stable")
        gt_st, vals = gt_st[order], vals[order]
        gt_T = np.tile(np.eye(4), (len(rows), 1, 1))
        gt_T[:, :3, :3] = quaternion_to_matrix(vals[:, 3:7])
        gt_T[:, :3, 3] = vals[:, :3]
    K, k_source = _read_K(folder, intrinsics, intrinsics_source)
    k_assumed = K is None
    if K is None:
        name = next((k for k in _TUM_K if k in str(folder.resolve()).lower()), None)
        fx, fy, cx, cy = _TUM_K[name] if name else _TUM_DEFAULT_K
        K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
        k_source = f"TUM {name} calibration" if name else "TUM default (525, 525, 319.5, 239.5)"
    frames = []
    for i, row in enumerate(depth_rows):
        s = _stamp_ns(row[0], str(folder / "depth.txt"))
        color = None
        if rgb_st.size:
            j = int(np.argmin(np.abs(rgb_st - s)))
            color = rgb[j][1]
        frames.append(FolderFrame(i, s, folder / row[1], color, None))
    return RGBDFolder(folder, "tum", frames, K, 5000.0, k_source, k_assumed, gt_st, gt_T,
                      notes=["TUM depth (1/5000 m) converted to millimetres"], warnings=folder_warnings)


def read_depth_mm(frame: FolderFrame, units_per_m: float) -> np.ndarray:
    """The frame's depth PNG as uint16 millimetres (unchanged for mm data; rounded for TUM's 1/5000 m)."""
    img = imread_quiet(frame.depth_path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise RecordingError(f"{frame.depth_path}: cannot read the depth image (missing, truncated or corrupt PNG)")
    if img.ndim != 2 or img.dtype != np.uint16:
        raise RecordingError(f"{frame.depth_path}: depth must be a single-channel 16-bit PNG, got {img.dtype} "
                             f"with shape {img.shape}")
    if units_per_m == 1000.0:
        return img
    mm = np.rint(img.astype(np.float64) * (1000.0 / units_per_m))
    return np.clip(mm, 0, 65535).astype(np.uint16)


def _secs(stamp_ns: int) -> str:
    return f"{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d}"


def _drop_unposed(chosen: list[FolderFrame], layout: str, warnings_: list[str]) -> tuple[list[FolderFrame], int]:
    """The 7-Scenes frames to write and how many were left out: a frame without a pose among posed frames is left
    out (fusion would otherwise interpolate a pose for it from its neighbours). Appends what was left out, and
    why, to warnings_. Frames that all lack a pose are all kept, without TF (fusion then tracks them)."""
    if layout != "7scenes":
        return chosen, 0
    unposed = [f for f in chosen if f.T_world_camera is None]
    reasons = {why: sum(f.pose_problem == why for f in unposed) for why in ("not finite", "missing")}
    text = ", ".join(f"pose.txt {why}: {n}" for why, n in reasons.items() if n)
    folder = chosen[0].depth_path.parent
    if len(unposed) == len(chosen):
        if reasons["not finite"]:
            warnings_.append(f"{folder}: none of the {len(chosen)} frames has a usable pose ({text}); written "
                             f"without TF")
        return chosen, 0
    if unposed:
        names = ", ".join(f.depth_path.name[: -len(".depth.png")] for f in unposed[:5])
        more = f", ... ({len(unposed) - 5} more)" if len(unposed) > 5 else ""
        warnings_.append(f"{folder}: {len(unposed)} of {len(chosen)} frames left out, they have no usable pose "
                         f"({text}): {names}{more}")
    return [f for f in chosen if f.T_world_camera is not None], len(unposed)


def _check_assumed_K(folder: RGBDFolder, width: int, height: int, warnings_: list[str]) -> None:
    """TUM's calibrations (and its default K) are for 640x480 images: RecordingError naming the intrinsics
    parameter for any other size. TUM's default is a guess, not a calibration: a warning says it was assumed."""
    if (width, height) != (640, 480):
        raise RecordingError(f"{folder.path}: no intrinsics file, and the {folder.k_source} K is for 640x480 "
                             f"images, these are {width}x{height}; give the depth camera's fx,fy,cx,cy",
                             parameter="intrinsics")
    if folder.k_source.startswith("TUM default"):
        warnings_.append(f"{folder.path}: no intrinsics file and no freiburg1/2/3 in the folder name; assumed "
                         f"the {folder.k_source} intrinsics, give the depth camera's own when known")
    else:
        folder.notes.append(f"K from the {folder.k_source} (named by the folder)")


def import_folder(src: str | os.PathLike, out: str | os.PathLike, rate: float = 30.0, frames: str | None = None,
                  color: str = "compressed", intrinsics: str | None = None, fmt: str | None = None,
                  compress: bool = True, quiet: bool = True, intrinsics_source: str = "intrinsics argument",
                  up=None, force: bool = False) -> dict:
    """Convert an RGB-D folder into a recording at `out` (.mcap, .bag, or a ROS 2 bag folder); return a summary.

    intrinsics: "fx,fy,cx,cy" when the folder has no intrinsics file; intrinsics_source: how the summary's
    K_source names them. up: the direction against gravity (x, y, z) in the folder's pose frame, when known;
    declared on /kinfu/world_up (the zero vector when not given: the frame is not taken for REP-103 z-up).
    The summary's warnings say what was doubtful (frames left out for want of a pose, an assumed K, ground
    truth that gives no pose). force: an entry of an earlier ROS 2 bag folder at `out` with a new file's name,
    edited since kinfu wrote it, is replaced.
    """
    up = None if up is None else check_up(up, "up")
    if color not in ("compressed", "raw", "none"):
        raise ConfigError(f"expected compressed, raw or none, got {color!r}", parameter="color")
    folder = scan_folder(src, rate=rate, intrinsics=parse_intrinsics(intrinsics), intrinsics_source=intrinsics_source)
    chosen = folder.frames[parse_frames(frames, len(folder.frames))]
    if not chosen:
        raise ConfigError(f"{frames!r} selects none of the {len(folder.frames)} frames of {folder.path}",
                          parameter="frames")
    warnings_ = list(folder.warnings)
    chosen, left_out = _drop_unposed(chosen, folder.layout, warnings_)
    out = Path(out)
    kind = format_for(out, fmt)
    compression = ({"mcap": "zstd", "bag": "lz4", "ros2": None}[kind]) if compress else None
    first = imread_quiet(chosen[0].depth_path, cv2.IMREAD_UNCHANGED)
    if first is None:
        raise RecordingError(f"{chosen[0].depth_path}: cannot read the depth image")
    height, width = first.shape[:2]
    if folder.k_assumed:
        _check_assumed_K(folder, width, height, warnings_)

    # TF samples: each frame's pose (7-Scenes), or ground truth around the chosen frames (TUM)
    tf_samples: list[tuple[int, np.ndarray]] = []
    if folder.layout == "7scenes":
        tf_samples = [(f.stamp_ns, f.T_world_camera) for f in chosen if f.T_world_camera is not None]
    elif folder.gt_stamps_ns is not None:
        lo, hi = chosen[0].stamp_ns - 100_000_000, chosen[-1].stamp_ns + 100_000_000
        sel = np.flatnonzero((folder.gt_stamps_ns >= lo) & (folder.gt_stamps_ns <= hi))
        tf_samples = [(int(folder.gt_stamps_ns[i]), folder.gt_poses[i]) for i in sel]
        if not tf_samples:
            gt = folder.gt_stamps_ns
            warnings_.append(f"{folder.path / 'groundtruth.txt'}: no ground-truth pose within the depth frames' "
                             f"time span ({_secs(chosen[0].stamp_ns)} .. {_secs(chosen[-1].stamp_ns)} s; ground "
                             f"truth spans {_secs(gt[0])} .. {_secs(gt[-1])} s); the recording has no camera poses")
    ortho = 0.0
    fixed = []
    for s, T in tf_samples:
        T = T.copy()
        ortho = max(ortho, float(np.abs(T[:3, :3] @ T[:3, :3].T - np.eye(3)).max()))
        T[:3, :3] = nearest_rotation(T[:3, :3])
        fixed.append((s, T))

    events: list[tuple[int, int, object]] = [(s, 0, T) for s, T in fixed]
    events += [(f.stamp_ns, 1, f) for f in chosen]
    events.sort(key=lambda e: (e[0], e[1]))
    color_topic = {"compressed": COLOR_TOPIC_COMPRESSED, "raw": COLOR_TOPIC_RAW, "none": None}[color]
    n_color = 0
    with RecordingWriter(out, fmt=kind, compression=compression, force=force) as w:
        w.write_vector(WORLD_UP_TOPIC, events[0][0], WORLD_FRAME, np.zeros(3) if up is None else up)
        for stamp, kind_i, item in progress(events, total=len(events), desc="import", quiet=quiet):
            if kind_i == 0:
                w.write_tf(stamp, [(WORLD_FRAME, CAMERA_FRAME, item)])
                continue
            f: FolderFrame = item
            depth = read_depth_mm(f, folder.depth_units_per_m)
            if depth.shape != (height, width):
                raise RecordingError(f"{f.depth_path}: depth is {depth.shape[1]}x{depth.shape[0]}, the first "
                                     f"frame was {width}x{height}")
            w.write_image(DEPTH_TOPIC, stamp, CAMERA_FRAME, depth, "16UC1")
            w.write_camera_info(INFO_TOPIC, stamp, CAMERA_FRAME, folder.K, width, height)
            if color_topic and f.color_path is not None:
                if color == "compressed":
                    data = f.color_path.read_bytes()
                    img_fmt = ("png" if data.startswith(_PNG_MAGIC) else "jpeg" if data.startswith(_JPEG_MAGIC)
                               else None)
                    if img_fmt is None:
                        raise RecordingError(f"{f.color_path}: not a JPEG or PNG file (first bytes {data[:8]!r})")
                    w.write_compressed_bytes(color_topic, stamp, CAMERA_FRAME, data, img_fmt)
                else:
                    bgr = imread_quiet(f.color_path, cv2.IMREAD_COLOR)
                    if bgr is None:
                        raise RecordingError(f"{f.color_path}: cannot read the colour image")
                    w.write_image(color_topic, stamp, CAMERA_FRAME, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), "rgb8")
                n_color += 1
    return {
        "source": str(folder.path), "layout": folder.layout, "output": str(out), "format": kind,
        "frames": len(chosen), "frames_in_folder": len(folder.frames), "frames_left_out": left_out,
        "color_frames": n_color, "tf_samples": len(fixed), "width": width, "height": height, "K": folder.K.tolist(),
        "K_source": folder.k_source, "max_rotation_orthonormality_error": ortho,
        "first_stamp_ns": chosen[0].stamp_ns, "last_stamp_ns": chosen[-1].stamp_ns,
        "topics": {"depth": DEPTH_TOPIC, "camera_info": INFO_TOPIC, "color": color_topic if n_color else None,
                   "tf": f"/tf {WORLD_FRAME} -> {CAMERA_FRAME}", "world_up": WORLD_UP_TOPIC},
        "up": None if up is None else up.tolist(),
        "notes": folder.notes, "warnings": warnings_,
    }


def dropped_frames_warning(source: str, stats: dict, lacking: str) -> str | None:
    """The depth frames a recording's export left out, by reason (as fuse reports the frames it dropped), and
    what the output lacks for them (`lacking` ... at their stamps); None when none was dropped. Said only in the
    stats, the export reads as the whole recording."""
    total = stats.get("dropped_total", 0)
    if not total:
        return None
    why = "; ".join(f"{reason}: {n}" for reason, n in stats["dropped"].items())
    return (f"{source}: {total} of the {stats['depth_messages']} depth frames dropped ({why}); {lacking} at their "
            f"stamps")


def _camera_change(recording, first, frame) -> str:
    """Why frames of two cameras (another K or image size: the camera info changed, or the depth images' size)
    cannot share a frame folder's one camera-intrinsics.txt."""

    def camera(f) -> str:
        fx, fy, cx, cy = f.K[0, 0], f.K[1, 1], f.K[0, 2], f.K[1, 2]
        return f"{f.depth.shape[1]}x{f.depth.shape[0]} fx={fx:.10g} fy={fy:.10g} cx={cx:.10g} cy={cy:.10g}"
    moved = (f" (K differs by up to {np.abs(frame.K - first.K).max():.3g} px)"
             if frame.depth.shape == first.depth.shape else "")
    return (f"{recording}: the depth camera changes at depth frame {frame.index} (stamp {frame.stamp_ns} ns): "
            f"{camera(frame)}, against {camera(first)} at frame {first.index}{moved}; a frame folder has one "
            f"camera-intrinsics.txt for all its frames: export the frames before and after apart (a start and end time each)")


def export_frames(recording: str | os.PathLike, out: str | os.PathLike, roles_kw: dict | None = None,
                  pose_source: str = "tf", pose_topic: str | None = None, tolerance_s: float = 0.05,
                  start_s: float | None = None, end_s: float | None = None, every: int = 1,
                  quiet: bool = True, force: bool = False) -> dict:
    """Write the assembled frames of a recording as a 7-Scenes-layout folder (the inverse of import_folder).

    frame-N.depth.png (uint16 mm, 0 = invalid), frame-N.color.png (when paired), frame-N.pose.txt
    (T_world_camera, when posed), camera-intrinsics.txt (the K of every frame: a camera whose K or image size
    changes is a RecordingError), frames.json (stamps, stats, roles, warnings: what was lost or assumed reading the
    recording). N is the depth message index. The folder appears only when every frame was written. force: an
    entry of an earlier folder at `out` with a new file's name, edited since kinfu wrote it, is replaced.
    """
    stats = FrameStats()
    listing = []
    with open_recording(recording) as rec:
        roles = detect_roles(rec, **(roles_kw or {}))
        total = rec.topics[roles.depth_topic].count if roles.depth_topic in rec.topics else None
        with atomic_dir(out, own=("frame-*", "camera-intrinsics.txt", "frames.json"), force=force) as tmp:
            K0 = None
            frames = iter_frames(rec, roles, pose_source=pose_source, pose_topic=pose_topic,
                                 tolerance_s=tolerance_s, start_s=start_s, end_s=end_s, every=every, stats=stats)
            for f in progress(frames, total=total, desc="export", quiet=quiet, unit="frame"):
                stem = tmp / f"frame-{f.index:06d}"
                mm = np.clip(np.rint(f.depth.astype(np.float64) * 1000.0), 0, 65535).astype(np.uint16)
                if not cv2.imwrite(f"{stem}.depth.png", mm):
                    raise RecordingError(f"{stem}.depth.png: cannot write")
                if f.color is not None:
                    cv2.imwrite(f"{stem}.color.png", cv2.cvtColor(f.color, cv2.COLOR_RGB2BGR))
                if f.T_world_camera is not None:
                    np.savetxt(f"{stem}.pose.txt", f.T_world_camera, fmt="%.17g")
                if K0 is None:
                    K0, first = f.K, f
                    np.savetxt(tmp / "camera-intrinsics.txt", K0, fmt="%.17g")
                elif f.depth.shape != first.depth.shape or np.abs(f.K - K0).max() > SAME_CAMERA_PX:
                    raise RecordingError(_camera_change(rec.path, first, f))
                listing.append({"index": f.index, "stamp_ns": f.stamp_ns, "color": f.color is not None,
                                "pose": f.T_world_camera is not None})
            if not listing:
                raise RecordingError(f"{rec.path}: no usable depth frame to export (dropped: "
                                     f"{stats.dropped or 'none'}, depth messages: {stats.depth_messages})")
            summary = {"recording": str(rec.path), "output": str(out), "roles": roles.as_dict(),
                       "frames": len(listing), "stats": stats.as_dict(), "K": K0.tolist(),
                       "warnings": rec.problems + stats.warnings(str(rec.path)), "list": listing}
            if dropped := dropped_frames_warning(str(rec.path), summary["stats"], "the folder has no frame"):
                summary["warnings"].append(dropped)
            (tmp / "frames.json").write_text(json.dumps(summary, indent=2) + "\n")
            umask = os.umask(0)
            os.umask(umask)
            tmp.chmod(0o777 & ~umask)  # mkdtemp made it 0700
    return summary
