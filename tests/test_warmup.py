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
