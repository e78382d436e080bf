"""Shared fixtures: paths to the bundled sample data and to ../shared/data (skip when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "sample_data"
SHARED_DATA = REPO.parent / "shared" / "data"


# entries of the repository's top folder when the run started: a test that writes into the working folder (a
# command run without -o writes its default output there) fails the run at its end (pytest_sessionfinish)
_TOP_ENTRIES: set[str] = set()
TOP_CACHES = {".pytest_cache", "__pycache__", ".coverage"}


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session):
    """With xdist workers, compile the numba kernels once first (kinfu_cli.warmup: two processes side by side
    instead of every worker compiling the same kernels for itself); KINFU_NO_WARM=1 skips it. A failure there only
    means the workers compile as before: the tests themselves judge the code."""
    config = session.config
    if hasattr(config, "workerinput"):
        return
    _TOP_ENTRIES.update(os.listdir(REPO))
    if not getattr(config.option, "numprocesses", None):
        return
    if os.environ.get("KINFU_NO_WARM") or os.environ.get("NUMBA_DISABLE_JIT"):
        return
    from kinfu_cli.warmup import warm

    warm()


def pytest_sessionfinish(session, exitstatus):
    """Fail the run when a test left a file or folder in the repository's top folder (the working folder of a
    run from the repository): outputs belong in the test's tmp_path."""
    if hasattr(session.config, "workerinput") or not _TOP_ENTRIES:
        return
    left = sorted(set(os.listdir(REPO)) - _TOP_ENTRIES - TOP_CACHES)
    if left:
        print(f"\ntests left {', '.join(left)} in {REPO}: write outputs under tmp_path")
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def shared_path(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test with the reason."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real data {p} not present (../shared/data is not checked out beside the repo)")
    return p


@pytest.fixture
def shared_data():
    return shared_path


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    p = SAMPLE / "tabletop"
    if not (p / "recording.mcap").exists():
        pytest.fail(f"{p}/recording.mcap missing: sample_data must be committed (kinfu synth -o {p})")
    return p


def one_line_error(res, *needles):
    """Assert a CliRunner result ended with exactly one `kinfu: error:` line (exit 2) holding `needles`."""
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    lines = [l for l in res.output.splitlines() if l.strip()]
    assert len(lines) == 1 and lines[0].startswith("kinfu: error: "), res.output
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


HAND_GROUPS = {"placements_removals": "placement", "pick_and_place": "pick-and-place"}


def write_hand_dataset(root: Path, seeds=range(3), user: str = "user9", groups=tuple(HAND_GROUPS),
                       **noise) -> Path:
    """A hand data set in the layout `kinfu eval poi` reads: per group (placements_removals: placements,
    pick_and_place) one synthetic task per seed, <user>_obj<seed>.traj with its labelled changes in
    <user>_obj<seed>.traj.res. `noise`: synth_hand_trajectory's noise_std (else its default)."""
    from kinfu_cli.io.polhemus import write_polhemus
    from kinfu_cli.sim.hand import random_task, synth_hand_trajectory

    for group in groups:
        for seed in seeds:
            traj, changes = synth_hand_trajectory(random_task(HAND_GROUPS[group], seed=seed), seed=seed, **noise)
            p = root / group / f"{user}_obj{seed}.traj"
            p.parent.mkdir(parents=True, exist_ok=True)
            write_polhemus(p, traj)
            (p.parent / (p.name + ".res")).write_text(
                "".join(f"{c.position[0]} {c.position[1]} {c.position[2]}\n" for c in changes))
    return root


def pytest_runtest_protocol(item, nextitem):
    """KINFU_TEST_CPU=FILE appends each test's CPU seconds (this process and its waited-for children) to FILE:
    on a loaded machine wall times rank tests badly."""
    path = os.environ.get("KINFU_TEST_CPU")
    if not path:
        return None
    import resource
    import time

    def cpu():
        return sum(resource.getrusage(who).ru_utime + resource.getrusage(who).ru_stime
                   for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))

    c0, t0 = cpu(), time.perf_counter()
    item.config.hook.pytest_runtest_logstart(nodeid=item.nodeid, location=item.location)
    from _pytest.runner import runtestprotocol

    runtestprotocol(item, nextitem=nextitem, log=True)
    item.config.hook.pytest_runtest_logfinish(nodeid=item.nodeid, location=item.location)
    with open(path, "a") as fh:
        fh.write(f"{cpu() - c0:.2f} {time.perf_counter() - t0:.2f} {item.nodeid}\n")
    return True


def small_tabletop_volume(seed: int = 3, *, voxel: float = 0.01, truncation: float = 0.04, frames: int = 3,
                          noise: bool = False, **volume_options):
    """A TernaryVolume of the primitive tabletop scene `seed` fused from `frames` 160x120 views of an orbit above it
    (the small fused volume several tests segment or write)."""
    from kinfu_cli.fusion.volume import TernaryVolume
    from kinfu_cli.sim.paths import orbit_poses
    from kinfu_cli.sim.scene import primitive_tabletop_scene
    from kinfu_cli.sim.sensor import DepthSensor, kinect_v1_intrinsics

    scene = primitive_tabletop_scene(seed)
    K = kinect_v1_intrinsics(160, 120)
    sensor = DepthSensor(K, 160, 120, noise=noise, seed=seed)
    vol = TernaryVolume(size=(1.28, 0.8, 0.4), voxel_size=voxel, origin=(-0.64, -0.4, 0.6), truncation=truncation,
                        min_depth=0.2, max_depth=2.0, **volume_options)
    for T in orbit_poses(frames, radius=0.85, height=1.3, target=(0, 0, 0.75)):
        depth, colour = sensor.render(scene, T)
        vol.integrate(depth, K, T, colour)
    return vol
