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

# not needed by a default `kinfu segment` (--quiet): 3D library, learners, batch, recordings, grasping, plots,
# viewer, progress bars, matplotlib (saliency.ply's viridis is a table)
HEAVY = ("open3d", "sklearn", "dask", "distributed", "mcap", "rosbags", "kinfu_cli.grasp",
         "kinfu_cli.report", "kinfu_cli.io.recording", "foxglove_schemas_protobuf", "tqdm", "matplotlib")


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


def test_mode_volume_read_without_hypotheses_segments_alike_and_refuses_fusion(tmp_path):
    """`kinfu segment` leaves a colour-mode volume's hypotheses (5x the rest of the file) unread: the colours it
    segments are the same winners, and such a volume cannot be fused into or saved (its hypotheses are missing)."""
    import pytest

    from kinfu_cli.core.errors import VolumeError
    from kinfu_cli.fusion.volume import TernaryVolume, load_volume
    from kinfu_cli.segmentation.pipeline import SegmentOptions, segment_volume
    from kinfu_cli.sim.paths import orbit_poses
    from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

    scene = primitive_tabletop_scene(3)
    K = kinect_v1_intrinsics(160, 120)
    sensor = DepthSensor(K, 160, 120, noise=False, seed=3)
    vol = TernaryVolume(size=(1.28, 0.8, 0.4), voxel_size=0.01, origin=(-0.64, -0.4, 0.6), truncation=0.04,
                        min_depth=0.2, max_depth=2.0, color_mode="mode")
    frames = [(*sensor.render(scene, T), T) for T in orbit_poses(4, radius=0.85, height=1.3, target=(0, 0, 0.75))]
    for depth, colour, T in frames[:3]:
        vol.integrate(depth, K, T, colour)
    vol.save(tmp_path / "volume.npz")
    full, light = load_volume(tmp_path / "volume.npz"), load_volume(tmp_path / "volume.npz", hypotheses=False)
    assert light.color_mode == "mode" and light.pool_hc.size == 0 and full.pool_hc.shape[0] == full.n_used > 0
    for a, b in zip(full.tsdf_weights(color=True), light.tsdf_weights(color=True)):
        assert np.array_equal(a, b)
    opts = SegmentOptions(superquadrics=False)
    segments = segment_volume(full, opts).to_json()["segments"]
    assert len(segments) >= 3 and segments == segment_volume(light, opts).to_json()["segments"]
    with pytest.raises(VolumeError, match="hypotheses"):
        light.integrate(frames[3][0], K, frames[3][2], frames[3][1])
    with pytest.raises(VolumeError, match="hypotheses"):
        light.save(tmp_path / "again.npz")
    full.integrate(frames[3][0], K, frames[3][2], frames[3][1])  # with them, fusion goes on (pools grow)
    assert full.n_used >= light.n_used
