"""ICP tracking loss and grid extent on real frames: `kinfu fuse --pose icp` on sub-sampled 7-Scenes frames tracks
within a voxel of the recorded poses; a frame it cannot track is counted, reported, not fused, and past
--max-lost fails the run; `--size auto` keeps the whole observed scene where a fixed 3 m grid cuts it."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import shared_path
from kinfu_cli.cli import cli
from kinfu_cli.core.grid import load_ternary
from kinfu_cli.fusion.extent import Survey, auto_grid
from kinfu_cli.fusion.volume import worst_case_bytes

VOXEL = 0.02  # coarse on purpose: a few seconds per run; the bounds below are stated in voxels


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def report_of(out):
    return json.loads((out / "report.json").read_text())


@pytest.fixture(scope="module")
def kitchen(tmp_path_factory):
    """Frames 0, 6, ..., 54 of the 7-Scenes kitchen (2 s of hand-held motion) as an MCAP with their TF poses."""
    root = shared_path("rgbd-7scenes-redkitchen")
    rec = tmp_path_factory.mktemp("kitchen") / "kitchen.mcap"
    res = run("import", root, "-o", rec, "--frames", "0:60:6", "--color", "none", "-q")
    assert res.exit_code == 0, res.output
    return root, rec


@pytest.mark.parametrize("every", [2, 3])
def test_icp_on_subsampled_kitchen_stays_within_half_a_voxel(kitchen, tmp_path, every):
    """Every 12th / 18th frame (0.4 / 0.6 s apart, up to 13 cm between frames): ICP tracks every frame and the
    tracked camera positions stay within a voxel of the recorded ones (RMS and worst frame: a model resolved at
    one voxel pins the camera no closer; drift, as the 6 cm of the issue, fails it), as the report says."""
    root, rec = kitchen
    out = tmp_path / "icp"
    res = run("fuse", rec, "-o", out, "--pose", "icp", "--every", every, "--voxel-size", VOXEL, "--quiet")
    assert res.exit_code == 0, res.output
    t = report_of(out)["tracking"]
    numbers = list(range(0, 60, 6))[::every]
    assert t["lost"] == 0 and t["tracked"] == len(numbers) - 1
    truth = [np.loadtxt(root / f"frame-{n:06d}.pose.txt") for n in numbers[1:]]
    err = np.array([np.linalg.norm(np.asarray(f["T_world_camera"])[:3, 3] - g[:3, 3])
                    for f, g in zip(t["frames"], truth)])
    ate = float(np.sqrt(np.mean(err ** 2)))
    print(f"kitchen every {6 * every}th frame: ATE {ate * 100:.2f} cm, max {err.max() * 100:.2f} cm")
    assert ate < VOXEL and err.max() < VOXEL
    assert t["ate_vs_given_m"]["rmse"] == pytest.approx(ate, abs=1e-4) and t["ate_vs_given_m"]["frames"] == len(err)
    # without tracking (camera assumed still) the error would be several times larger
    still = np.sqrt(np.mean([np.sum((g[:3, 3] - np.loadtxt(root / "frame-000000.pose.txt")[:3, 3]) ** 2)
                             for g in truth]))
    assert ate < still / 3


# one grid for the runs compared voxel by voxel (it holds the kitchen frames 0-24)
GRID = ["--size", "4", "--origin", "-3,-1.6,0"]


def _folder(folder, kitchen_root, numbers, box_at=None):
    """A 7-Scenes-layout folder of kitchen frames (symlinks); at frame `box_at` the depth image is a real
    close-range frame of another scene (the tabletop box, as if held in front of the camera)."""
    box_root = shared_path("rgbd-tabletop-box")
    folder.mkdir()
    (folder / "camera-intrinsics.txt").symlink_to(kitchen_root / "camera-intrinsics.txt")
    for n in numbers:
        name = f"frame-{n:06d}"
        (folder / f"{name}.pose.txt").symlink_to(kitchen_root / f"{name}.pose.txt")
        depth = box_root / "frame-000055.depth.png" if n == box_at else kitchen_root / f"{name}.depth.png"
        (folder / f"{name}.depth.png").symlink_to(depth)
    rec = folder.with_suffix(".mcap")
    res = run("import", folder, "-o", rec, "--color", "none", "-q")
    assert res.exit_code == 0, res.output
    return rec


@pytest.fixture(scope="module")
def occluded(tmp_path_factory):
    """Kitchen frames 0, 6, 12, 18, 24 with frame 12 occluded by the box (ICP cannot track it), and the same
    recording without frame 12."""
    root = shared_path("rgbd-7scenes-redkitchen")
    tmp = tmp_path_factory.mktemp("occluded")
    return (root, _folder(tmp / "occluded", root, range(0, 25, 6), box_at=12),
            _folder(tmp / "reference", root, (0, 6, 18, 24)))


def test_a_lost_frame_fails_the_run_past_max_lost(occluded, tmp_path):
    """1 lost frame is more than 10 % of the 5 selected: the run stops there with one line naming --max-lost
    (exit 2) and writes nothing."""
    _, rec, _ = occluded
    out = tmp_path / "out"
    res = run("fuse", rec, "-o", out, "--pose", "icp", "--voxel-size", VOXEL, "--quiet")
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: --max-lost:"), res.output
    assert "lost 1 of 2 tracked frames (50 %): frames 2; stopped" in lines[0]
    assert not out.exists() or not any(out.iterdir())


def test_a_lost_frame_is_reported_and_not_fused(occluded, tmp_path):
    """Allowed up to 25 %: the run finishes with a warning; the frame is in report.json as lost (with its fitness
    and agreement) and is not fused: volume and tracked poses are those of the recording without it."""
    root, rec, reference = occluded
    out, ref = tmp_path / "out", tmp_path / "ref"
    res = run("fuse", rec, "-o", out, "--pose", "icp", "--voxel-size", VOXEL, *GRID, "--max-lost", "25%")
    assert res.exit_code == 0, res.output
    assert "kinfu: warning: tracking (icp) lost 1 of 4 tracked frames (25 %): frames 2; they were not fused" \
        in res.stderr
    assert "(1 dropped, 1 lost by tracking)" in res.stdout
    r = report_of(out)
    t = r["tracking"]
    assert t["lost"] == 1 and t["lost_frames"] == [2] and t["tracked"] == 4
    lost = t["frames"][1]
    assert lost["index"] == 2 and lost["lost"] and lost["T_world_camera"] is None and lost["reason"]
    assert lost["fitness"] < 0.3 or lost["agreement"] < 0.75
    assert lost["attempts"] >= 2  # re-localisation was tried first
    assert r["frames"]["used"] == 4 and r["grid"]["frames_in_volume"] == 4
    assert r["frames"]["dropped"] == {"tracking lost (not fused)": 1}
    assert r["frames"]["used"] + r["frames"]["dropped_total"] == r["frames"]["depth_messages"] == 5
    # tracking went on after the lost frame within a voxel of the recorded poses
    dev = np.array([f["given_minus_tracked_m"] for f in t["frames"] if not f["lost"]])
    assert len(dev) == 3 and dev.max() < VOXEL
    # the same as never having seen the frame
    res = run("fuse", reference, "-o", ref, "--pose", "icp", "--voxel-size", VOXEL, *GRID, "--quiet")
    assert res.exit_code == 0, res.output
    kept = [f for f in t["frames"] if not f["lost"]]
    for a, b in zip(kept, report_of(ref)["tracking"]["frames"]):
        np.testing.assert_allclose(a["T_world_camera"], b["T_world_camera"], atol=1e-4)
    a, b = load_ternary(out / "ternary.npz").labels, load_ternary(ref / "ternary.npz").labels
    assert (a == b).mean() > 0.9999


def test_max_lost_values(occluded, tmp_path):
    _, rec, _ = occluded
    for bad in ("ten", "150%", "-0.1"):
        res = run("fuse", rec, "-o", tmp_path / "o", "--pose", "icp", "--max-lost", bad, "--quiet")
        assert res.exit_code == 2 and res.output.startswith("kinfu: error: --max-lost:"), res.output
        assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------------------------- grid extent

def test_auto_size_keeps_the_kitchen_a_3m_grid_cuts(kitchen, tmp_path):
    """Forced (TF) poses: a 3 m grid centred on the first frames cuts the kitchen (occupied voxels on its faces,
    a warning); with no size option the grid holds everything observed: no face touched, no voxel lost."""
    _, rec = kitchen
    fixed, auto = tmp_path / "fixed", tmp_path / "auto"
    res = run("fuse", rec, "-o", fixed, "--voxel-size", VOXEL, "--size", "3", "--quiet")
    assert res.exit_code == 0, res.output
    rf = report_of(fixed)
    assert rf["grid"]["sizing"] == {"mode": "given"}
    touched = [f for f, n in rf["grid"]["face_contacts"].items() if n]
    assert touched and "kinfu: warning: occupied voxels touch the grid faces" in res.stderr
    res = run("fuse", rec, "-o", auto, "--voxel-size", VOXEL)
    assert res.exit_code == 0, res.output
    assert "kinfu: note: grid auto-sized to" in res.stderr and "GiB budget" in res.stderr
    assert "warning" not in res.stderr
    ra = report_of(auto)
    assert ra["grid"]["sizing"]["mode"] == "auto" and ra["warnings"] == []
    assert not any(ra["grid"]["face_contacts"].values())
    # the auto grid holds the 3 m grid's occupied box and goes on beyond each face the 3 m grid touched
    fb, ab = rf["bounding_box"]["occupied"], ra["bounding_box"]["occupied"]
    for axis, name in enumerate("xyz"):  # within a voxel and a half: the two grids sample the surface at other phases
        assert ab["min"][axis] <= fb["min"][axis] + 1.5 * VOXEL and ab["max"][axis] >= fb["max"][axis] - 1.5 * VOXEL
        if f"{name}-" in touched:
            assert ab["min"][axis] < fb["min"][axis] - VOXEL
        if f"{name}+" in touched:
            assert ab["max"][axis] > fb["max"][axis] + VOXEL
    assert ra["counts"]["occupied"] > rf["counts"]["occupied"]
    # the auto grid is no bigger than the observed box plus its margin
    s = ra["grid"]["sizing"]
    extent = np.array(s["observed_max"]) - np.array(s["observed_min"])
    assert np.all(np.array(ra["grid"]["size_m"]) < extent + 0.5)


def test_auto_size_keeps_the_sample_scene(sample_dir, tmp_path):
    """The demo's first fusion (no size option) on the sample recording: every occupied voxel off the grid's faces,
    while the old default (3 m centred on the first frames) cut the floor."""
    out = tmp_path / "auto"
    res = run("fuse", sample_dir / "recording.mcap", "-o", out, "--end", "3", "--voxel-size", "0.01", "--quiet")
    assert res.exit_code == 0, res.output
    r = report_of(out)
    assert r["grid"]["sizing"]["mode"] == "auto" and r["warnings"] == []
    assert not any(r["grid"]["face_contacts"].values())
    box = r["bounding_box"]["occupied"]
    assert np.all(np.array(box["voxels_min"]) > 0) and np.all(np.array(box["voxels_max"]) < r["grid"]["shape"])


def _survey(points, cameras=((0.0, 0.0, 1.0),)):
    return Survey(np.asarray(points, dtype=np.float64), np.asarray(cameras, dtype=np.float64), 1, 0.0)


def test_auto_grid_box_margin_and_budget():
    rng = np.random.default_rng(0)
    pts = rng.uniform((-3, -2, 0), (3, 2, 2.5), size=(20000, 3))  # a 6 x 4 x 2.5 m room
    # within the budget: the box plus margin (truncation + 2 voxels) at the default voxel
    g = auto_grid(_survey(pts), voxel_size=None, resolution=None, truncation=0.03, color=True, budget=2**40)
    margin = 0.03 + 2 * g.voxel_size
    assert g.voxel_size == pytest.approx(3 / 512) and g.capped == ""
    assert np.allclose(g.origin, pts.min(axis=0) - margin)
    assert np.all(g.origin + np.array(g.size) >= pts.max(axis=0) + margin - 1e-9)
    # a 1 GiB budget: the default voxel coarsens until the worst case fits
    g = auto_grid(_survey(pts), voxel_size=None, resolution=None, truncation=0.03, color=True, budget=2**30)
    assert g.worst_case_bytes <= 2**30 and g.worst_case_bytes == worst_case_bytes(g.shape, True)
    assert g.voxel_size > 3 / 512 and "coarsened" in g.capped
    assert np.all(g.origin + np.array(g.size) >= pts.max(axis=0))
    # a given voxel size stays; the box shrinks around the densest part (a dense table in the corner)
    table = rng.uniform((1.5, 1.0, 0.7), (2.5, 1.8, 0.8), size=(50000, 3))
    g = auto_grid(_survey(np.concatenate([pts, table])), voxel_size=0.01, resolution=None, truncation=0.03,
                  color=False, budget=2**26)
    assert g.voxel_size == 0.01 and "cropped" in g.capped and g.worst_case_bytes <= 2**26
    lo, hi = g.origin, g.origin + np.array(g.size)
    assert np.mean(np.all((table >= lo) & (table <= hi), axis=1)) > 0.95
    # resolution N with auto: N voxels along each axis, the box inside
    g = auto_grid(_survey(pts), voxel_size=None, resolution=128, truncation=0.03, color=False, budget=2**40)
    assert g.shape == (128, 128, 128)
    assert np.all(g.origin <= pts.min(axis=0)) and np.all(g.origin + np.array(g.size) >= pts.max(axis=0))


def test_max_memory_coarsens_the_default_voxel(kitchen, tmp_path):
    _, rec = kitchen
    out = tmp_path / "out"
    res = run("fuse", rec, "-o", out, "--max-memory", "0.01", "--no-color")
    assert res.exit_code == 0, res.output
    assert "voxel coarsened from 5.86 to" in res.stderr
    g = report_of(out)["grid"]
    assert g["sizing"]["worst_case_GiB"] <= 0.01 and g["voxel_size"] > 3 / 512
    res = run("fuse", rec, "-o", tmp_path / "o2", "--max-memory", "0", "--quiet")
    assert res.exit_code == 2 and res.output.startswith("kinfu: error: --max-memory:"), res.output
