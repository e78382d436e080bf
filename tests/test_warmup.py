"""The set-up's kernel warm-up (kinfu_cli.warmup): it runs real commands, and names what failed."""

from __future__ import annotations

from pathlib import Path

from kinfu_cli import warmup
from kinfu_cli.cli import COMMANDS


def test_every_job_runs_an_existing_command(tmp_path):
    jobs = warmup.jobs(Path("rec.mcap"), Path("gt"), tmp_path)
    assert set(jobs) == {"fusion", "planning"}
    commands = set(COMMANDS)
    for job in jobs.values():
        for args in job:
            assert args[0] in commands, args


def test_a_failing_command_is_named(tmp_path):
    failed = warmup.run_job([["fuse", str(tmp_path / "missing.mcap"), "-o", str(tmp_path / "out")]])
    assert len(failed) == 1 and failed[0].startswith("kinfu fuse: kinfu: error:") and "missing.mcap" in failed[0]


def test_no_sample_recording_is_not_a_failure(tmp_path):
    assert warmup.warm(sample=tmp_path) == []


def test_kernel_sources_are_the_files_that_define_kernels():
    pkg = Path(warmup.__file__).parent
    assert warmup.KERNEL.search((pkg / "fusion" / "icp.py").read_text())
    assert not warmup.KERNEL.search((pkg / "warmup.py").read_text())
    assert not warmup.KERNEL.search((pkg / "nbv" / "contours.py").read_text())  # names njit, defines none


def test_reader_kernels_run_as_the_readers_call_them():
    same, coloured = warmup.reader_kernels()
    assert same and coloured == 12  # the colour camera at the depth camera's place colours every pixel


def test_api_kernels_find_the_voxel_and_the_wall():
    hits, wall = warmup.api_kernels()
    assert hits == 3  # the three rays towards +x hit voxel (2, 2, 2), the one towards -x leaves
    assert wall == 48  # every pixel of the 8x6 view sees the wall it fused at 0.5 m


ONE_TYPE_SET = """
import numpy as np
from kinfu_cli.core.grid import EMPTY, OCCUPIED, UNKNOWN, TernaryGrid
from kinfu_cli.fusion import kernels
from kinfu_cli.fusion.volume import TernaryVolume
from kinfu_cli.nbv import contours, raycast

labels = np.full((16, 16, 16), EMPTY, np.int8)
labels[8:, :, :] = UNKNOWN
labels[5, 5, 5] = OCCUPIED
grid = TernaryGrid(labels, np.zeros(3), 0.05)
vol = raycast.RayVolume.from_grid(grid)
raycast.RayVolume.from_grid(TernaryGrid(np.full((16, 16, 16), EMPTY, np.int8), np.zeros(3), 0.05))
dirs = np.array([[1.0, 0, 0], [0, 1.0, 0]])
raycast.cast_rays(vol, np.array([0.1, 0.1, 0.1]), dirs)
raycast.cast_rays(vol, np.full((2, 3), 0.1), dirs)
contours.contour_voxels(labels)
contours.contour_voxels(labels, np.full(labels.shape, 9, np.uint8))
tsdf = TernaryVolume(size=0.5, voxel_size=0.05, min_depth=0.1)
tsdf.prepare_depth(np.ones((6, 8), np.float32))
tsdf.prepare_depth(np.ones((6, 16), np.float32)[:, ::2])
print([len(k.signatures) for k in (raycast._cast_kernel, raycast._fill_bricks, contours._frontier_normals,
                                   kernels.clean_depth)])
"""


def test_a_kernel_is_compiled_for_one_set_of_argument_types():
    # each second set of types was a second compilation in the tests and in users' first runs (the per-ray
    # caster's read-only origins: 35 s): a broadcast origin, a grid without mixed blocks, contours without
    # weights, a strided depth image all reach the kernels with the types the warm-up compiled
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", ONE_TYPE_SET], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["[1,", "1,", "1,", "1]"]
