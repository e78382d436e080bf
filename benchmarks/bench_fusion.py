"""Fusion benchmark: kinfu TernaryVolume vs open3d UniformTSDFVolume on the same frames and grid.

Run:  .venv/bin/python benchmarks/bench_fusion.py [--frames N] [--resolution 512] [--size 3.0] [--skip-7scenes]
      [--placement scene|camera|both]
Prints, per data set: frames/s of both (integration only, same process, same frames, the two volumes
fed alternately frame by frame so that load from other processes hits both alike), the speed ratio,
the cost of the colour mode filter (a third volume with color_mode "mode", fed alike: time mode / mean),
OctoMap (pyoctomap, the `[bench]` extra: insertPointCloud with ray casting at the same voxel size) on the
first --octomap-frames frames (it needs tens of seconds per 640x480 frame, so its fps is extrapolated from those),
and the share of voxels with the same ternary label (over the whole grid and over the voxels either
volume observed). Then, in fresh subprocesses, the peak RSS (VmHWM) of a 512^3 volume with colour fusing
the 7-Scenes frames and reading them out (labels, mesh, save), as it comes and with every block stored.
Also printed: CPU ms per frame of each (process time, all threads: less sensitive to other processes than
wall time on a shared machine) and the 1-minute load average at the end. Not a test: the numbers go into the
fusion report.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from kinfu_cli.fusion import kernels as kn  # noqa: E402
from kinfu_cli.fusion.placement import default_origin  # noqa: E402
from kinfu_cli.fusion.volume import TernaryVolume  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _seven_scenes import SEVEN, seven_scenes_frames  # noqa: E402



def synthetic_frames(n: int, width: int = 640, height: int = 480):
    from kinfu_cli.core.camera import preset_intrinsics
    from kinfu_cli.sim.paths import orbit_poses
    from kinfu_cli.sim.scene import box_scene
    from kinfu_cli.sim.sensor import DepthSensor

    K = preset_intrinsics("kinect_v1", width, height)
    sensor = DepthSensor(K, width, height, noise=False)  # exact depth
    scene = box_scene()
    out = []
    for T in orbit_poses(n, radius=1.0, height=0.8, span_deg=120):
        d, c = sensor.render(scene, T)
        out.append((d, c, K, T))
    return out


def _open3d_labels(vol, res):
    tw = np.asarray(vol.extract_volume_tsdf())  # (N, 2) float64, voxel x * res^2 + y * res + z
    labels = np.zeros(tw.shape[0], dtype=np.int8)
    known = tw[:, 1] > 0
    labels[known & (tw[:, 0] <= 0)] = 1
    labels[known & (tw[:, 0] > 0)] = -1
    return labels.reshape(res, res, res)


def _world_points(d, K, T, max_depth):
    """Back-projected valid depth pixels of one frame in the world frame (N, 3) float64."""
    v, u = np.nonzero((d > 0) & (d <= max_depth))
    z = d[v, u].astype(np.float64)
    cam = np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z], axis=1)
    return cam @ T[:3, :3].T + T[:3, 3]


def _octomap_tree(res, size):
    """An OctoMap OcTree at the grid's voxel size, or the reason it is not available."""
    try:
        import pyoctomap
    except ImportError as exc:  # the [bench] extra is not installed
        return None, f"pyoctomap not importable ({exc}); pip install -e '.[bench]'"
    return pyoctomap.OcTree(size / res), None


def compare(name, frames, res, size, trunc, max_depth, placement="scene", with_mode=True, octo_frames=0):
    """Both volumes side by side, frame by frame (open3d, then ours, for each frame), so that load from
    other processes on a shared machine hits both alike. Integration calls only are timed.

    placement "scene": the grid centred on what the first frames observe (kinfu fuse's default; most of the
    grid lies in the frustum); "camera": centred on the first camera (half the grid lies behind it, so
    open3d, which visits every voxel, skips more of them)."""
    import open3d as o3d  # heavy: only for the comparison

    if placement == "scene":
        origin = default_origin([(d, K, T) for d, c, K, T in frames[:5]], size, max_depth=max_depth)
    else:
        origin = frames[0][3][:3, 3] - 0.5 * size
    d, c, K, T = frames[0]
    # JIT warm-up (cached on disk after the first run) on a tiny grid
    for cm in ("mean", "mode"):
        TernaryVolume(size=size, resolution=16, origin=origin, truncation=size / 16, min_depth=0.0,
                      max_depth=max_depth, color_mode=cm).integrate(d, K, T, c)
    ref = o3d.pipelines.integration.UniformTSDFVolume(
        length=size, resolution=res, sdf_trunc=trunc,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.RGB8, origin=np.asarray(origin, float).reshape(3, 1))
    ours = TernaryVolume(size=size, resolution=res, origin=origin, truncation=trunc, min_depth=0.0,
                         max_depth=max_depth, color=True)
    mode = TernaryVolume(size=size, resolution=res, origin=origin, truncation=trunc, min_depth=0.0,
                         max_depth=max_depth, color=True, color_mode="mode") if with_mode else None
    t_mode = 0.0
    octo, octo_why = _octomap_tree(res, size) if octo_frames > 0 else (None, "not run")
    t_octo, t_ours_octo, n_octo, n_octo_points = 0.0, 0.0, 0, 0
    h, w = d.shape
    t_ref = t_ours = cpu_ref = cpu_ours = 0.0
    stats = None
    for d, c, K, T in frames:
        intr = o3d.camera.PinholeCameraIntrinsic(w, h, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray(c)), o3d.geometry.Image(d), depth_scale=1.0,
            depth_trunc=max_depth, convert_rgb_to_intensity=False)
        extrinsic = np.linalg.inv(T)
        t0, p0 = time.perf_counter(), time.process_time()
        ref.integrate(rgbd, intr, extrinsic)
        t1, p1 = time.perf_counter(), time.process_time()
        stats = ours.integrate(d, K, T, c)
        t2, p2 = time.perf_counter(), time.process_time()
        t_ref += t1 - t0
        t_ours += t2 - t1
        cpu_ref += p1 - p0
        cpu_ours += p2 - p1
        if octo is not None and n_octo < octo_frames:
            # full rays from the camera to every valid depth point (free space cleared, endpoints occupied)
            pts = _world_points(d, K, T, max_depth)
            t3 = time.perf_counter()
            octo.insertPointCloud(pts, np.asarray(T[:3, 3], dtype=np.float64), max_range=max_depth)
            t_octo += time.perf_counter() - t3
            t_ours_octo += t2 - t1
            n_octo += 1
            n_octo_points += len(pts)
        if mode is not None:
            t3 = time.perf_counter()
            mode.integrate(d, K, T, c)
            t_mode += time.perf_counter() - t3
    fps_o3d, fps_ours = len(frames) / t_ref, len(frames) / t_ours
    lab_o3d = _open3d_labels(ref, res)
    del ref
    gc.collect()
    lab_ours = ours.labels()
    same = lab_ours == lab_o3d
    observed = (lab_ours != 0) | (lab_o3d != 0)
    result = {
        "data": name, "placement": placement, "frames": len(frames), "image": [w, h], "resolution": res,
        "size_m": size, "truncation_m": trunc,
        "open3d_fps": round(fps_o3d, 2), "kinfu_fps": round(fps_ours, 2), "speedup": round(fps_ours / fps_o3d, 2),
        # CPU time of the process (all threads) per frame: less sensitive to other processes' load than wall time
        "open3d_cpu_ms_per_frame": round(cpu_ref / len(frames) * 1e3, 1),
        "kinfu_cpu_ms_per_frame": round(cpu_ours / len(frames) * 1e3, 1), "load_1min": round(os.getloadavg()[0], 1),
        "same_label_all": round(float(same.mean()) * 100, 3),
        "same_label_observed": round(float(same[observed].mean()) * 100, 3),
        "counts_kinfu": {k: int(np.count_nonzero(lab_ours == v)) for k, v in (("occupied", 1), ("empty", -1))},
        "counts_open3d": {k: int(np.count_nonzero(lab_o3d == v)) for k, v in (("occupied", 1), ("empty", -1))},
        "blocks_stored": ours.n_blocks_allocated, "kinfu_grid_MB": round(ours.memory_bytes() / 2**20, 1),
        "last_frame": stats,
    }
    if n_octo:
        # ratio against kinfu's time on the same frames (the first ones), measured alongside
        result.update(octomap_frames=n_octo, octomap_points_per_frame=n_octo_points // n_octo,
                      octomap_s_per_frame=round(t_octo / n_octo, 2), octomap_fps=round(n_octo / t_octo, 4),
                      octomap_leaf_nodes=int(octo.getNumLeafNodes()),
                      kinfu_fps_same_frames=round(n_octo / t_ours_octo, 2),
                      speedup_vs_octomap=round(t_octo / t_ours_octo, 1),
                      octomap_60_frames_extrapolated_s=round(t_octo / n_octo * len(frames), 1))
    elif octo_frames > 0:
        result["octomap"] = octo_why
    if mode is not None:
        result.update(kinfu_mode_fps=round(len(frames) / t_mode, 2), mode_over_mean_time=round(t_mode / t_ours, 2),
                      kinfu_mode_grid_MB=round(mode.memory_bytes() / 2**20, 1))
        del mode
    del lab_o3d, lab_ours, same, observed, ours
    gc.collect()
    return result


def _peak_rss_mb() -> float:
    """VmHWM of this process (ru_maxrss would include the parent's peak: it survives exec on Linux)."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def rss_child(res: int, size: float, n: int, worst: bool = False) -> None:
    """Build a res^3 colour volume from the 7-Scenes frames (synthetic ones without the data), read it out
    (labels, mesh, save); print peak RSS. With worst: every block gets per-voxel storage first."""
    frames = seven_scenes_frames(60) if SEVEN.exists() else synthetic_frames(n)
    origin = default_origin([(d, K, T) for d, c, K, T in frames[:5]], size)
    vol = TernaryVolume(size=size, resolution=res, origin=origin, color=True)
    base = _peak_rss_mb()
    if worst:
        cls = np.full(int(np.prod(vol.nb)), kn.VOXEL, dtype=np.uint8)
        vol._ensure_capacity(cls.size)
        vol.n_used = kn.allocate_blocks(cls, vol.block_idx.reshape(-1), vol.block_w.reshape(-1), vol.pool_v,
                                        vol.pool_w, vol.pool_c, vol.n_used)
    for d, c, K, T in frames:
        vol.integrate(d, K, T, c)
    del frames
    lab = vol.labels()
    mesh = vol.extract_mesh()
    with tempfile.TemporaryDirectory() as tmp:
        vol.save(Path(tmp) / "volume.npz")
    del lab, mesh
    peak = _peak_rss_mb()
    print(json.dumps({"resolution": res, "color": True, "all_blocks_stored": worst, "peak_rss_MB": round(peak, 1),
                      "rss_before_fusing_MB": round(base, 1), "blocks_stored": vol.n_blocks_allocated,
                      "grid_MB": round(vol.memory_bytes() / 2**20, 1),
                      "worst_case_grid_MB": round(vol.bytes_worst_case / 2**20, 1)}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=30, help="synthetic frames (7-Scenes uses up to 60)")
    ap.add_argument("--resolution", type=int, default=512)
    ap.add_argument("--size", type=float, default=3.0)
    ap.add_argument("--truncation", type=float, default=0.03)
    ap.add_argument("--max-depth", type=float, default=4.0)
    ap.add_argument("--seven-frames", type=int, default=60, help="7-Scenes frames (0..N-1, at most 60)")
    ap.add_argument("--placement", choices=("scene", "camera", "both"), default="both",
                    help="grid centred on the observed scene (kinfu fuse's default), on the first camera, or both")
    ap.add_argument("--skip-synthetic", action="store_true")
    ap.add_argument("--skip-7scenes", action="store_true")
    ap.add_argument("--skip-rss", action="store_true")
    ap.add_argument("--skip-mode", action="store_true", help="no colour mode filter volume")
    ap.add_argument("--octomap-frames", type=int, default=3,
                    help="frames OctoMap inserts (0: none; its fps is extrapolated from these)")
    ap.add_argument("--rss-child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--rss-worst", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.rss_child:
        rss_child(a.resolution, a.size, a.frames, a.rss_worst)
        return
    placements = ("scene", "camera") if a.placement == "both" else (a.placement,)
    data = []
    if not a.skip_synthetic:
        data.append(("synthetic 640x480 tabletop", synthetic_frames(a.frames)))
    if not a.skip_7scenes and SEVEN.exists():
        frames = seven_scenes_frames(a.seven_frames)
        data.append((f"7-Scenes redkitchen 0-{len(frames) - 1}", frames))
    for name, frames in data:
        for placement in placements:
            print(json.dumps(compare(name, frames, a.resolution, a.size, a.truncation, a.max_depth, placement,
                                     not a.skip_mode, a.octomap_frames)),
                  flush=True)
    del data
    if not a.skip_rss:
        for extra in ([], ["--rss-worst"]):
            out = subprocess.run([sys.executable, __file__, "--rss-child", "--resolution", str(a.resolution),
                                  "--size", str(a.size), "--frames", str(a.frames), *extra],
                                 capture_output=True, text=True, check=True)
            print(out.stdout.strip().splitlines()[-1], flush=True)


if __name__ == "__main__":
    main()
