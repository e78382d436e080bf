"""Reading benchmark: kinfu's frame assembly and TF lookups against plain reference code in the same process.

1. Frames: `iter_frames` (decode depth + colour, pair by stamp, camera pose through a 9-link TF chain) on a
   640x480 recording in each container, against the reference "rosbags AnyReader + deserialize + decode the
   same depth and colour messages" with no pairing and no poses. The ratio is kinfu's overhead over bare decoding.
2. TF: `TfBuffer.lookup_many` of N stamps through the same chain, against scipy (Slerp per link, vectorised
   over the stamps, composed with numpy) — both vectorised; then against a per-stamp `lookup` loop.

Run:  .venv/bin/python benchmarks/bench_io.py [--frames 60] [--stamps 20000]
Not a test: the numbers go into the io report.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from scipy.spatial.transform import Rotation, Slerp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from kinfu_cli.io.frames import iter_frames  # noqa: E402
from kinfu_cli.io.messages import decode_color, decode_depth  # noqa: E402
from kinfu_cli.io.recording import open_recording  # noqa: E402
from kinfu_cli.io.tf_buffer import TfBuffer  # noqa: E402
from kinfu_cli.io.writers import RecordingWriter  # noqa: E402

W, H = 640, 480
CHAIN = ["world", "base_link", "link1", "link2", "link3", "link4", "link5", "link6", "wrist", "camera_optical"]


def _link_pose(j: int, t: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.1 * np.sin(t + j), 0.2 * np.cos(0.5 * t), 0.05 * j * t]).as_matrix()
    T[:3, 3] = [0.1 * j, 0.02 * t, 0.3]
    return T


def write_recording(path: Path, n: int) -> Path:
    rng = np.random.default_rng(0)
    depth = (rng.random((H, W)) * 3000 + 500).astype(np.uint16)
    yy, xx = np.mgrid[0:H, 0:W]
    color = np.dstack([xx % 256, yy % 256, (xx + yy) % 256]).astype(np.uint8)
    K = np.array([[525.0, 0, 319.5], [0, 525.0, 239.5], [0, 0, 1]])
    t0 = 1_700_000_000 * 10**9
    with RecordingWriter(path, compression={".mcap": "zstd", ".bag": "lz4"}.get(path.suffix)) as w:
        w.write_tf(t0, [("world", "base_link", np.eye(4)), ("wrist", "camera_optical", np.eye(4))], static=True)
        for k in range(int(n / 30 * 100) + 20):  # 100 Hz arm
            t = t0 + k * 10_000_000
            w.write_tf(t, [(CHAIN[j], CHAIN[j + 1], _link_pose(j, k / 100)) for j in range(1, 8)])
            i = k * 30 // 100
            if k % 10 in (0, 3, 7) and i < n:  # ~30 Hz frames
                w.write_image("/camera/depth/image_raw", t + 1, "camera_optical", depth + i, "16UC1")
                w.write_compressed_image("/camera/color/image_raw/compressed", t + 2_000_000, "camera_optical",
                                         color, "jpeg")
                w.write_camera_info("/camera/depth/camera_info", t + 1, "camera_optical", K, W, H)
    return path


def bench_frames(path: Path) -> dict:
    # reference: deserialize and decode the same messages, nothing else
    t = time.perf_counter()
    n_ref = 0
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/camera/depth/image_raw",
                                                              "/camera/color/image_raw/compressed")]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic.endswith("image_raw"):
                decode_depth(msg)
                n_ref += 1
            else:
                decode_color(msg)
    t_ref = time.perf_counter() - t

    t = time.perf_counter()
    with open_recording(path) as rec:
        frames = sum(1 for f in iter_frames(rec) if f.T_world_camera is not None and f.color is not None)
    t_ours = time.perf_counter() - t

    # the part of it spent reading /tf (a pass of its own: in MCAP and bags TF shares chunks with the images)
    t = time.perf_counter()
    with open_recording(path) as rec:
        TfBuffer.from_recording(rec)
    t_tf = time.perf_counter() - t
    return {"container": path.name, "frames": frames, "reference_frames": n_ref,
            "kinfu_s": round(t_ours, 3), "of_which_tf_pass_s": round(t_tf, 3), "reference_s": round(t_ref, 3),
            "kinfu_fps": round(frames / t_ours, 1), "ratio_kinfu_over_reference": round(t_ours / t_ref, 2)}


def bench_tf(n_stamps: int) -> dict:
    tf = TfBuffer()
    tf.add("world", "base_link", 0, np.eye(4), static=True)
    tf.add("wrist", "camera_optical", 0, np.eye(4), static=True)
    samples = np.arange(0, 6000) * 10_000_000  # 60 s at 100 Hz
    link_T = {j: np.stack([_link_pose(j, s * 1e-9) for s in samples]) for j in range(1, 8)}
    for j in range(1, 8):
        for s, T in zip(samples, link_T[j]):
            tf.add(CHAIN[j], CHAIN[j + 1], int(s), T)
    rng = np.random.default_rng(1)
    stamps = np.sort(rng.integers(samples[0], samples[-1], n_stamps))
    tf.lookup_many("world", "camera_optical", stamps[:10])  # build the sorted arrays once

    t = time.perf_counter()
    ours = tf.lookup_many("world", "camera_optical", stamps)
    t_ours = time.perf_counter() - t

    t = time.perf_counter()
    ref = np.broadcast_to(np.eye(4), (n_stamps, 4, 4)).copy()
    for j in range(1, 8):
        Ts = link_T[j]
        slerp = Slerp(samples, Rotation.from_matrix(Ts[:, :3, :3]))
        E = np.zeros((n_stamps, 4, 4))
        E[:, :3, :3] = slerp(stamps).as_matrix()
        for c in range(3):
            E[:, c, 3] = np.interp(stamps, samples, Ts[:, c, 3])
        E[:, 3, 3] = 1
        ref = ref @ E
    t_ref = time.perf_counter() - t

    m = min(n_stamps, 500)
    t = time.perf_counter()
    for s in stamps[:m]:
        tf.lookup("world", "camera_optical", int(s))
    t_loop = (time.perf_counter() - t) * n_stamps / m
    return {"stamps": n_stamps, "links": 9, "kinfu_lookup_many_s": round(t_ours, 4),
            "scipy_slerp_reference_s": round(t_ref, 4), "ratio_kinfu_over_scipy": round(t_ours / t_ref, 2),
            "per_stamp_lookup_loop_s_extrapolated": round(t_loop, 3),
            "speedup_vs_per_stamp_loop": round(t_loop / t_ours, 1),
            "max_abs_difference": float(np.abs(ours - ref).max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--stamps", type=int, default=20000)
    args = ap.parse_args()
    out = {"frames": [], "tf": None}
    with tempfile.TemporaryDirectory() as d:
        for name in ("bench.mcap", "bench.bag", "bench_ros2"):
            path = write_recording(Path(d) / name, args.frames)
            out["frames"].append(bench_frames(path))
    out["tf"] = bench_tf(args.stamps)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
