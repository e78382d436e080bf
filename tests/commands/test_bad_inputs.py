"""Bad input of every class ends in one line `kinfu: error: ...` naming the file, topic, link or option (exit 2):
broken TF chains and loops, frames and topics named but absent or of the wrong type, numbers that are NaN,
inf, absurd or out of range, damaged volume and JSON files, absurd trajectories, corrupt images (without the
codec libraries' own lines on stderr), and the messages that used to blame the wrong thing."""

from __future__ import annotations

import json
import shutil
import signal
import zipfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import VolumeError
from kinfu_cli.fusion.volume import load_grid
from kinfu_cli.io.recording import open_recording
from kinfu_cli.io.writers import RecordingWriter

FUSE_FAST = ["--every", "10", "--size", "1", "--resolution", "32", "--quiet"]


@contextmanager
def time_limit(seconds: int):
    """Fail (instead of hanging the suite) when the block runs longer than `seconds`."""
    def on_alarm(*_):
        raise TimeoutError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def run(*args, limit: int = 60):
    with time_limit(limit):
        return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(res, *needles: str) -> str:
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: "), res.output
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


# ------------------------------------------------------------------------------------------- TF
def rewrite_tf(src: Path, dst: Path, mutate) -> Path:
    """Copy a recording message by message; each TransformStamped of /tf and /tf_static passes `mutate`."""
    with open_recording(src) as rec, RecordingWriter(dst) as w:
        for topic, msgtype, log_ns, msg in rec.typed_messages():
            if msgtype == "tf2_msgs/msg/TFMessage":
                for t in msg.transforms:
                    mutate(t)
            w._write(topic, msgtype, log_ns, msg)
    return dst


def _on_link4(change):
    """A mutation of the link link3 -> link4 of the sample's arm (world -> base_link -> link1 .. link6 -> wrist
    -> camera_optical)."""
    def mutate(t):
        if t.child_frame_id == "link4":
            change(t)
    return mutate


def _quat(x, y, z, w):
    def change(t):
        r = t.transform.rotation
        r.x, r.y, r.z, r.w = x, y, z, w
    return change


def _set(path: str, value):
    def change(t):
        obj = t
        *parents, last = path.split(".")
        for p in parents:
            obj = getattr(obj, p)
        setattr(obj, last, value)
    return change


BROKEN = {  # name: (mutation of link3 -> link4, what the error says about it)
    "nan_quaternion": (_quat(float("nan"), 0.0, 0.0, 1.0), "non-finite quaternion"),
    "zero_quaternion": (_quat(0.0, 0.0, 0.0, 0.0), "zero quaternion"),
    "long_quaternion": (_quat(0.0, 0.0, 0.0, 2.0), "not of unit length"),
    "inf_translation": (_set("transform.translation.x", float("inf")), "non-finite translation"),
    "self_link": (_set("header.frame_id", "link4"), "two different"),
    "missing_link": (_set("child_frame_id", "link4_renamed"), "no parent link"),
}


@pytest.fixture(scope="module")
def broken_tf(sample_dir, tmp_path_factory):
    """The sample MCAP with its TF damaged in each way of BROKEN, plus a loop (link4's parent becomes link6)."""
    out = tmp_path_factory.mktemp("broken_tf")
    paths = {name: rewrite_tf(sample_dir / "recording.mcap", out / f"{name}.mcap", _on_link4(change))
             for name, (change, _) in BROKEN.items()}
    paths["loop"] = rewrite_tf(sample_dir / "recording.mcap", out / "loop.mcap",
                               _on_link4(_set("header.frame_id", "link6")))
    return paths


@pytest.mark.parametrize("name", list(BROKEN))
def test_a_broken_camera_chain_is_an_error_naming_the_link_not_another_world_frame(broken_tf, name, tmp_path):
    """Before: fuse exited 0 with world_frame 'link4' although 'world' exists."""
    why = BROKEN[name][1]
    line = one_line_error(run("fuse", broken_tf[name], "-o", tmp_path / "out", *FUSE_FAST),
                          f"{name}.mcap", "camera_optical", "'link4'", "'world'", why)
    assert "link4_renamed" not in line
    assert not (tmp_path / "out").exists()
    one_line_error(run("export", broken_tf[name], "-o", tmp_path / "exp"), "'link4'", "'world'")
    # info shows the tree, names no world frame, and says what is broken
    res = run("info", broken_tf[name], "--json")
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert s["roles"]["world_frame"] is None and s["roles"]["camera_frame"] == "camera_optical"
    assert "'link4'" in s["tf"]["problem"] and why in s["tf"]["problem"]
    if name != "missing_link":  # the rejected transforms are counted on their link
        [item] = s["tf"]["rejected_links"]
        assert item["child"] == "link4" and sum(item["rejected"].values()) == 165
    # naming the world frame explicitly uses the chain that is left (the user's decision, not a silent one)
    res = run("info", broken_tf[name], "--json", "--world-frame", "link4")
    assert res.exit_code == 0 and json.loads(res.output)["roles"]["world_frame"] == "link4"


def test_a_tf_loop_is_reported_not_walked_forever(broken_tf, tmp_path):
    """Before: info / fuse / export looped forever, memory growing 40-80 MB/s."""
    line = one_line_error(run("fuse", broken_tf["loop"], "-o", tmp_path / "out", *FUSE_FAST, limit=30),
                          "loop.mcap", "loop")
    assert all(f in line for f in ("link4", "link5", "link6"))
    one_line_error(run("export", broken_tf["loop"], "-o", tmp_path / "exp", limit=30), "loop")
    res = run("info", broken_tf["loop"], limit=30)
    assert res.exit_code == 0, res.output
    assert "loop (its frames are not in the tree above): link4 -> link5 -> link6 -> link4" in res.output
    assert "world frame:    -" in res.output and "problem:" in res.output
    one_line_error(run("info", broken_tf["loop"], "--frames", limit=30), "loop")


@pytest.mark.parametrize("flag", ["--camera-frame", "--world-frame", "--hand-frame"])
def test_named_frames_must_exist(sample_dir, tmp_path, flag):
    """Before: fuse with a --camera-frame that does not exist switched silently to ICP."""
    for cmd in (["fuse", sample_dir / "recording.mcap", "-o", tmp_path / "out", *FUSE_FAST],
                ["info", sample_dir / "recording.mcap"]):
        one_line_error(run(*cmd, flag, "nope"), flag, "'nope'", "is not in the TF tree", "camera_optical")
    assert not (tmp_path / "out").exists()


def test_a_topic_of_the_wrong_type_is_named_with_its_type(sample_dir, tmp_path):
    """Before: --depth-topic /tf ended in an AttributeError traceback."""
    rec = sample_dir / "recording.mcap"
    for cmd in (["info", rec, "--frames"], ["fuse", rec, "-o", tmp_path / "o", *FUSE_FAST],
                ["export", rec, "-o", tmp_path / "e"]):
        one_line_error(run(*cmd, "--depth-topic", "/tf"), "--depth-topic", "/tf", "tf2_msgs/msg/TFMessage",
                       "sensor_msgs/msg/Image")
    one_line_error(run("info", rec, "--info-topic", "/hand/pose"), "--info-topic", "geometry_msgs/msg/PoseStamped",
                   "sensor_msgs/msg/CameraInfo")


# ------------------------------------------------------------------------------------------- numbers
@pytest.mark.parametrize("args, flag", [
    (["info", "{rec}", "--frames", "--tolerance", "nan"], "--tolerance"),
    (["info", "{rec}", "--frames", "--tolerance", "inf"], "--tolerance"),
    (["info", "{rec}", "--frames", "--start", "nan"], "--start"),
    (["info", "{rec}", "--frames", "--start", "inf"], "--start"),
    (["info", "{rec}", "--frames", "--end", "1e300"], "--end"),
    (["fuse", "{rec}", "-o", "{out}", "--start", "inf"], "--start"),
    (["fuse", "{rec}", "-o", "{out}", "--resolution", "nan"], "--resolution"),  # int(nan): a traceback
    (["fuse", "{rec}", "-o", "{out}", "--resolution", "64,inf,64"], "--resolution"),
    (["fuse", "{rec}", "-o", "{out}", "--size", "inf"], "--size"),
    (["fuse", "{rec}", "-o", "{out}", "--origin", "0,nan,0"], "--origin"),
    # an empty value or list item was read as the default or skipped (a fuzz pass, 2026-11-29)
    (["fuse", "{rec}", "-o", "{out}", "--origin", ""], "--origin"),
    (["fuse", "{rec}", "-o", "{out}", "--camera-frame", ""], "--camera-frame"),
    (["poi", "{rec}", "-o", "{out}", "--workspace", ""], "--workspace"),
    (["eval", "poi", "{gt}", "--speed", "1,,2"], "--speed"),
    (["eval", "segment", "--sweep", "--sweep-values", "1,,2", "--scenes", "0"], "--sweep-values"),
    (["synth", "-o", "{out}", "--frames", "3", "--width", "32", "--height", "24", "--formats", "mcap,,bag"],
     "--formats"),
    (["synth", "-o", "{out}", "--frames", "3", "--width", "32", "--height", "24", "--hand-rate", "inf"],
     "--hand-rate"),  # a traceback
    (["synth", "-o", "{out}", "--scene", "room", "--frames", "3", "--frame-rate", "1e309"], "--frame-rate"),
    (["grasp", "{vol}", "-o", "{out}", "--palm-width", "0"], "--palm-width"),  # a hand of no size grasped
    (["export", "{rec}", "-o", "{out}", "--tolerance", "nan"], "--tolerance"),
    (["poi", "{rec}", "-o", "{out}", "--reg-space", "1e300"], "--reg-space"),
    (["poi", "{rec}", "-o", "{out}", "--bic-threshold", "nan"], "--bic-threshold"),
    (["poi", "{rec}", "-o", "{out}", "--neighbours", "1000000000"], "--neighbours"),
    (["segment", "{vol}", "-o", "{out}", "--resolution", "1e-6"], "--resolution"),
    (["segment", "{vol}", "-o", "{out}", "--spatial-importance", "nan"], "--spatial-importance"),
    (["segment", "{vol}", "-o", "{out}", "--sanity-angle", "nan"], "--sanity-angle"),
    (["segment", "{vol}", "-o", "{out}", "--concave-cut", "2"], "--concave-cut"),
    (["nbv", "{vol}", "--pois", "{pois}", "-o", "{out}", "--radius", "1e300"], "--radius"),
    (["nbv", "{vol}", "--pois", "{pois}", "-o", "{out}", "--poi-radius", "1e300"], "--poi-radius"),
    (["eval", "nbv", "{gt}", "--width", "0"], "--width"),
    (["eval", "nbv", "{gt}", "--oscillation", "nan"], "--oscillation"),
    (["eval", "fusion", "{fused}", "--ground-truth", "{gt}", "--spacing", "1e300"], "--spacing"),
])
def test_bad_numbers_are_refused_naming_the_option(args, flag, sample_dir, fused, tmp_path):
    """NaN, inf, absurd and out-of-range values: refused before any work (before: tracebacks, hangs, or silently
    used / replaced by a default)."""
    values = {"rec": sample_dir / "recording.mcap", "out": tmp_path / "out", "vol": fused / "volume.npz",
              "pois": fused / "pois.json", "gt": sample_dir / "ground_truth", "fused": fused}
    one_line_error(run(*[a.format(**values) for a in args], limit=30), flag, "expected")
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def fused(sample_dir, tmp_path_factory):
    """A small fusion of the sample and its POIs: volume.npz, ternary.npz, pois.json."""
    out = tmp_path_factory.mktemp("fused") / "fuse"
    res = run("fuse", sample_dir / "recording.mcap", "-o", out, "--every", "5", "--size", "1", "--resolution", "64",
              "--quiet", limit=300)
    assert res.exit_code == 0, res.output
    res = run("poi", sample_dir / "recording.mcap", "-o", out / "pois.json")
    assert res.exit_code == 0, res.output
    return out


def _folder(tmp_path: Path, shared_data, n: int = 3) -> Path:
    """The first n 7-Scenes frames with their intrinsics."""
    src = shared_data("rgbd-7scenes-redkitchen")
    dst = tmp_path / "frames"
    dst.mkdir()
    for i in range(n):
        for p in src.glob(f"frame-{i:06d}.*"):
            shutil.copy(p, dst / p.name)
    shutil.copy(src / "camera-intrinsics.txt", dst)
    return dst


@pytest.mark.parametrize("extra, needles", [
    (["--intrinsics", "nan,585,320,240"], ["--intrinsics", "finite"]),
    (["--rate", "nan"], ["--rate"]),
    (["--rate", "1e-12"], ["--rate"]),
    (["--rate", "inf"], ["--rate"]),
])
def test_import_refuses_bad_numbers(tmp_path, shared_data, extra, needles):
    folder = _folder(tmp_path, shared_data)
    (folder / "camera-intrinsics.txt").unlink()
    args = ["import", folder, "-o", tmp_path / "out.mcap"]
    if "--intrinsics" not in extra:
        args += ["--intrinsics", "585,585,320,240"]
    one_line_error(run(*args, *extra), *needles)
    assert not (tmp_path / "out.mcap").exists()


def test_import_refuses_a_non_rigid_pose_naming_the_file(tmp_path, shared_data):
    """Before: a scaled rotation was projected onto the nearest rotation without a word."""
    folder = _folder(tmp_path, shared_data)
    (folder / "frame-000001.pose.txt").write_text("2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n")
    one_line_error(run("import", folder, "-o", tmp_path / "out.mcap"), "frame-000001.pose.txt",
                   "not a rigid transform")


@pytest.mark.parametrize("row, why", [
    ("1.1 0 0 0 0 0 0 0", "quaternion of length 0"),
    ("1.1 0 0 0 0 0 0 5", "quaternion of length 5"),
    ("1.1 0 nan 0 0 0 0 1", "not finite"),
    ("1.1 0 0 1e300 0 0 0 1", "translation beyond"),
    ("99999999999999999999.1 0 0 0 0 0 0 1", "timestamp"),
])
def test_a_bad_tum_ground_truth_names_the_file(tmp_path, shared_data, row, why):
    src = _folder(tmp_path, shared_data, n=2)
    tum = tmp_path / "tum"
    (tum / "depth").mkdir(parents=True)
    for i in range(2):
        shutil.copy(src / f"frame-{i:06d}.depth.png", tum / "depth" / f"{i}.png")
    (tum / "depth.txt").write_text("1.0 depth/0.png\n1.033 depth/1.png\n")
    (tum / "groundtruth.txt").write_text(f"1.0 0 0 0 0 0 0 1\n{row}\n")
    one_line_error(run("import", tum, "-o", tmp_path / "tum.mcap"), "groundtruth.txt", why)


def test_corrupt_images_are_one_line_without_codec_chatter(tmp_path, shared_data, capfd):
    """libpng prints "libpng error: ..." itself (fd 2, below Python); OpenCV logs "[ WARN...]" lines. Neither may
    appear before kinfu's line. capfd sees what C code writes to the real stderr; CliRunner sees Python's."""
    folder = _folder(tmp_path, shared_data)
    data = bytearray((folder / "frame-000002.depth.png").read_bytes())
    for i in range(100, len(data), 301):  # damage the compressed stream, keep the header
        data[i] ^= 0x55
    (folder / "frame-000002.depth.png").write_bytes(bytes(data))
    capfd.readouterr()
    one_line_error(run("import", folder, "-o", tmp_path / "a.mcap"), "frame-000002.depth.png",
                   "cannot read the depth image")
    (folder / "frame-000001.color.jpg").write_bytes(b"GIF89a not a jpeg")
    one_line_error(run("import", folder, "-o", tmp_path / "b.mcap"), "frame-000001.color.jpg", "not a JPEG or PNG")
    captured = capfd.readouterr()
    assert "libpng" not in captured.err and "WARN" not in captured.err and "JPEG" not in captured.err, captured.err


# ------------------------------------------------------------------------------------------- files
def _damaged_volumes(fused: Path, out: Path) -> dict[str, Path]:
    vol = (fused / "volume.npz").read_bytes()
    flipped = bytearray(vol)
    for i in range(200, len(flipped), 997):
        flipped[i] ^= 0xFF
    files = {"truncated.npz": vol[: len(vol) // 3], "flipped.npz": bytes(flipped), "empty.npz": b""}
    for name, data in files.items():
        (out / name).write_bytes(data)
    d = dict(np.load(fused / "ternary.npz"))
    d["origin"] = np.array([np.nan, 0.0, 0.0])
    np.savez(out / "nan_origin.npz", **d)
    return {name: out / name for name in [*files, "nan_origin.npz"]}


def test_damaged_volume_files_are_one_line_naming_the_file(fused, tmp_path, sample_dir):
    """Before: BadZipFile tracebacks in nbv, segment, fuse --init; a NaN origin was blamed on pois.json."""
    for name, path in _damaged_volumes(fused, tmp_path).items():
        for cmd in (["nbv", path, "--pois", fused / "pois.json", "-o", tmp_path / "v.json"],
                    ["segment", path, "-o", tmp_path / "seg"]):
            line = one_line_error(run(*cmd), str(path))
            assert "pois.json" not in line
        if name != "nan_origin.npz":
            one_line_error(run("fuse", sample_dir / "recording.mcap", "-o", tmp_path / "f", "--init", path,
                               "--quiet"), str(path))
    assert "'origin' is [nan" in one_line_error(run("segment", tmp_path / "nan_origin.npz", "-o", tmp_path / "s"))


def test_volume_readers_raise_only_volume_errors_on_mutated_files(fused, tmp_path):
    """Seeded byte flips, zeroed ranges and truncations of volume.npz and ternary.npz: VolumeError or a grid."""
    rng = np.random.default_rng(11)
    for name in ("volume.npz", "ternary.npz"):
        good = (fused / name).read_bytes()
        for k in range(20):
            data = bytearray(good)
            kind = k % 3
            if kind == 0:
                for i in rng.integers(0, len(data), 1 + k):
                    data[i] ^= int(rng.integers(1, 256))
            elif kind == 1:
                a, n = int(rng.integers(0, len(data))), int(rng.integers(1, 4096))
                data[a:a + n] = bytes(len(data[a:a + n]))
            else:
                data = data[: int(rng.integers(0, len(data)))]
            path = tmp_path / f"{k}_{name}"
            path.write_bytes(bytes(data))
            try:
                grid = load_grid(path)
            except VolumeError as exc:
                assert str(path) in str(exc)
            else:
                assert grid.labels.ndim == 3 and np.all(np.isfinite(grid.origin))


def test_a_volume_with_no_observation_says_so(sample_dir, tmp_path):
    """Before: a grid placed away from every reading ended in "could not write mesh.ply"."""
    one_line_error(run("fuse", sample_dir / "recording.mcap", "-o", tmp_path / "far", "--origin", "100,100,100",
                       *FUSE_FAST), "nothing was observed", "[100.000, 101.000]")
    assert not (tmp_path / "far").exists()


def test_deeply_nested_json_is_one_line(fused, sample_dir, tmp_path):
    """Before: RecursionError tracebacks."""
    nested = tmp_path / "nested.json"
    nested.write_text('{"pois": ' + "[" * 100_000 + "]" * 100_000 + "}")
    one_line_error(run("nbv", fused / "ternary.npz", "--pois", nested, "-o", tmp_path / "v.json"), "nested.json")
    one_line_error(run("fuse", sample_dir / "recording.mcap", "-o", tmp_path / "f", "--clear-pois", nested,
                       *FUSE_FAST), "nested.json")
    one_line_error(run("nbv", fused / "ternary.npz", "--pois", fused / "pois.json", "--candidates", nested,
                       "-o", tmp_path / "v.json"), "nested.json")


def test_a_trajectory_far_from_any_origin_is_refused(tmp_path):
    """Finite coordinates near 1e200-1e300 used to reach an assertion inside GMM-AS."""
    path = tmp_path / "huge.mcap"
    with RecordingWriter(path) as w:
        for i in range(300):
            T = np.eye(4)
            T[:3, 3] = [1e250 * np.sin(i / 10), 1e200 * i, 1e300]
            w.write_pose("/hand/pose", 10**9 + i * 10**7, "world", T)
    one_line_error(run("poi", path, "-o", tmp_path / "p.json"), "huge.mcap", "/hand/pose", "1e+06 m")


def test_a_recording_is_read_by_its_first_bytes_whatever_its_name(sample_dir, tmp_path):
    """Before: an MCAP named .bag failed with a UTF-8 decoding error."""
    for src, name in (("recording.mcap", "mcap_named.bag"), ("recording.bag", "bag_named.mcap"),
                      ("recording.mcap", "no_suffix")):
        shutil.copy(sample_dir / src, tmp_path / name)
        res = run("info", tmp_path / name, "--json")
        assert res.exit_code == 0, res.output
        assert json.loads(res.output)["message_count"] == 769


def test_zip_of_the_wrong_kind_is_a_volume_error(tmp_path):
    path = tmp_path / "other.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("ternary.npy", b"not an npy file")
    with pytest.raises(VolumeError, match="other.npz"):
        load_grid(path)


def _raw_poses(path: Path, topic: str, quats) -> Path:
    """PoseStamped messages with the given orientation quaternions, as they are (RecordingWriter.write_pose would
    make them unit from a matrix)."""
    with RecordingWriter(path) as w:
        for i, (x, y, z, qw) in enumerate(quats):
            stamp = 10**9 + i * 10**8
            pose = w._type("geometry_msgs/msg/Pose")(
                position=w._type("geometry_msgs/msg/Point")(x=0.1 * i, y=0.0, z=0.5),
                orientation=w._type("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=qw))
            msg = w._type("geometry_msgs/msg/PoseStamped")(header=w._header(topic, stamp, "world"), pose=pose)
            w._write(topic, "geometry_msgs/msg/PoseStamped", stamp, msg)
    return path


@pytest.mark.parametrize("bad", [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 3.0), (float("nan"), 0.0, 0.0, 1.0)])
def test_pose_topics_with_bad_quaternions_name_topic_and_sample(tmp_path, bad):
    from kinfu_cli.core.errors import RecordingError, TrajectoryError
    from kinfu_cli.io.frames import _PosePath
    from kinfu_cli.io.hand import load_hand_trajectory

    path = _raw_poses(tmp_path / "poses.mcap", "/hand/pose", [(0.0, 0.0, 0.0, 1.0)] * 3 + [bad])
    with pytest.raises(TrajectoryError, match=r"poses.mcap:/hand/pose: sample 3 has the orientation quaternion"):
        load_hand_trajectory(path)
    with open_recording(path) as rec, pytest.raises(RecordingError, match=r"poses.mcap: pose topic /hand/pose: "
                                                                          r"the pose at stamp 1300000000 ns"):
        _PosePath(rec, "/hand/pose", 0)


def test_eval_fusion_into_a_folder_nothing_can_be_made_in_fails_before_its_warnings(sample_dir, fused, tmp_path):
    # the run used to score first, print its warning, then fail to write: now one line, before the work
    if not Path("/proc/self").is_dir():
        pytest.skip("needs Linux /proc, where nothing can be made")
    res = run("eval", "fusion", fused, "--ground-truth", sample_dir / "ground_truth", "--quiet", "-o",
              "/proc/x/a.json", limit=60)
    one_line_error(res, "--output", "cannot write into the folder /proc")
