"""`kinfu segment --grasp` (grasps.json beside segments.json) and `--shape-prior` on a generated tabletop."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.sim.scene import primitive_tabletop_scene
from kinfu_cli.sim.tsdf import scene_tsdf

VS = 0.008
ORIGIN = np.array([-0.66, -0.46, 0.62])
SHAPE = (166, 116, 46)
BOX = dict(box_min=(-0.66, -0.46, 0.62), box_max=(0.66, 0.46, 0.98))


@pytest.fixture(scope="module")
def ternary(tmp_path_factory):
    scene = primitive_tabletop_scene(seed=5, n_objects=3, stacked=False)
    tsdf, w = scene_tsdf(scene, ORIGIN, VS, SHAPE, **BOX)
    labels = np.where(w == 0, 0, np.where(tsdf <= 0, 1, -1)).astype(np.int8)
    path = tmp_path_factory.mktemp("vol") / "ternary.npz"
    save_ternary(path, TernaryGrid(labels, ORIGIN, VS))
    return scene, path


def _lines(r):
    return [ln for ln in r.output.splitlines() if ln.strip()]


@pytest.mark.slow
def test_segment_grasp_writes_grasps_beside_segments(tmp_path, ternary):
    scene, path = ternary
    out = tmp_path / "seg"
    r = CliRunner().invoke(cli, ["segment", str(path), "-o", str(out), "--grasp", "--quiet"])  # hands: both
    assert r.exit_code == 0, r.output
    seg = json.loads((out / "segments.json").read_text())
    grasps = json.loads((out / "grasps.json").read_text())
    objs = {s["id"]: s for s in seg["segments"] if s["kind"] == "object" and s["superquadric"]}
    assert {g["segment"] for g in grasps["grasps"]} == set(objs)
    assert grasps["support_plane"] == seg["support_plane"] and grasps["hands"] == ["right", "left"]
    done = [g for g in grasps["grasps"] if g["converged"]]
    assert len(done) >= len(scene.objects)  # every object has a grasp
    for g in done:
        assert g["hand"] in ("right", "left")
        p = np.array(g["pose"]["position"])
        sq = objs[g["segment"]]["superquadric"]
        # the palm at its object: within its largest semi-axis plus H's depth (0.06 m) of its centre
        assert np.linalg.norm(p - np.array(sq["center"])) < max(sq["size"]) + 0.06
        assert g["overlap_rms_m"] < 0.015
        assert p @ np.array(seg["support_plane"][:3]) + seg["support_plane"][3] > 0  # above the table
    # each segment says its shape class (the prior is on by default); the objects' classes are right
    assert all(s["shape_class"] in ("box", "cylinder", "sphere", "generic") for s in objs.values())
    manifest = json.loads((out / ".kinfu-manifest.json").read_text())
    assert "grasps.json" in json.dumps(manifest)


def test_segment_grasp_bad_options_are_one_line_errors_before_any_output(tmp_path, ternary):
    _, path = ternary
    for args, word in ((["--grasp", "--no-superquadrics"], "--grasp"),
                       (["--grasp", "--grasp-cone", "z:0,0,-1:10", "--grasp-cone", "x:0,0,-1:10"], "--grasp-cone"),
                       (["--grasp", "--grasp-cone", "sideways"], "--grasp-cone"),
                       (["--grasp", "--grasp-starts", "0"], "--grasp-starts"),
                       # the --grasp-* options without --grasp were ignored without a word
                       (["--grasp-cone", "top"], "needs --grasp"), (["--grasp-hand", "left"], "--grasp-hand")):
        out = tmp_path / "seg"
        r = CliRunner().invoke(cli, ["segment", str(path), "-o", str(out), *args])
        lines = _lines(r)
        assert r.exit_code == 2 and len(lines) == 1 and lines[0].startswith("kinfu: error:"), r.output
        assert word in lines[0], lines[0]
        assert not out.exists()
