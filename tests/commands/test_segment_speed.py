"""`kinfu segment` starts light (issue 12: <= 2 s end to end on the 512^3 volume): the command module and a
default run import none of the libraries the default path does not need (open3d alone took 0.4 s)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from kinfu_cli.core.grid import TernaryGrid, save_ternary
from kinfu_cli.sim.scene import primitive_tabletop_scene
from kinfu_cli.sim.tsdf import scene_tsdf

# not needed by a default `kinfu segment`: 3D library, learners, batch, recordings, grasping, plots, viewer
HEAVY = ("open3d", "sklearn", "dask", "distributed", "mcap", "rosbags", "kinfu_cli.grasp",
         "kinfu_cli.report", "kinfu_cli.io.recording", "foxglove_schemas_protobuf")


def _loaded(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys\nprint('LOADED', json.dumps(sorted(m for m in "
                          f"{HEAVY!r} if m in sys.modules)))"], capture_output=True, text=True, check=True).stdout
    return json.loads(out.split("LOADED", 1)[1])


def test_segment_command_module_imports_no_heavy_library():
    assert _loaded("import json\nimport kinfu_cli.cli\nimport kinfu_cli.commands.segment") == []


def test_default_segment_run_imports_no_heavy_library(tmp_path):
    scene = primitive_tabletop_scene(0, n_objects=3, stacked=False)
    tsdf, w = scene_tsdf(scene, (-0.66, -0.46, 0.62), 0.008, (165, 115, 45))
    labels = np.where(w == 0, 0, np.where(tsdf <= 0, 1, -1)).astype(np.int8)
    save_ternary(tmp_path / "ternary.npz", TernaryGrid(labels, np.array([-0.66, -0.46, 0.62]), 0.008))
    out = tmp_path / "seg"
    code = ("import json\nfrom kinfu_cli.cli import cli\n"
            f"code = cli.main(['segment', {str(tmp_path / 'ternary.npz')!r}, '-o', {str(out)!r}, '--quiet'], "
            "standalone_mode=False)\nassert code in (0, None), code")
    assert _loaded(code) == []
    doc = json.loads((out / "segments.json").read_text())
    assert doc["support_plane"] is not None and sum(s["kind"] == "object" for s in doc["segments"]) >= 3
    assert (out / "segments.ply").stat().st_size > 0 and (out / "saliency.ply").stat().st_size > 0
