"""kinfu installed where its user cannot write (kinfu_cli/__init__ points numba's kernel cache elsewhere)."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

import kinfu_cli
from kinfu_cli import warmup
from conftest import SAMPLE

PACKAGE = Path(kinfu_cli.__file__).parent


@pytest.fixture
def read_only_install(tmp_path):
    """A copy of the package whose __pycache__ folders cannot be made, even by root: each is a file (and the
    copy is read-only, for a user that is not root). Yields the folder to put on PYTHONPATH."""
    site = tmp_path / "site"
    shutil.copytree(PACKAGE, site / "kinfu_cli", ignore=shutil.ignore_patterns("__pycache__"))
    folders = [p for p in site.rglob("*") if p.is_dir()] + [site]
    for d in folders:
        (d / "__pycache__").touch()
    for p in [*site.rglob("*"), site]:
        p.chmod(p.stat().st_mode & ~0o222)
    yield site
    for p in [*site.rglob("*"), site]:
        p.chmod(p.stat().st_mode | stat.S_IWUSR)


def run_zvc(site: Path, cwd: Path, home: Path) -> subprocess.CompletedProcess:
    """`kinfu poi --algorithm zvc` (compiles its kernel) from the copy, with this HOME and TMPDIR cwd/tmp."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
    (cwd / "tmp").mkdir()
    env.update(PYTHONPATH=str(site), HOME=str(home), TMPDIR=str(cwd / "tmp"))
    return subprocess.run([sys.executable, "-m", "kinfu_cli", "poi", str(SAMPLE / "tabletop" / "recording.mcap"),
                           "--algorithm", "zvc", "-o", "pois.json"], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


def test_a_read_only_install_caches_kernels_in_the_users_cache(read_only_install, tmp_path, monkeypatch):
    home = tmp_path / "home"
    home.mkdir()
    res = run_zvc(read_only_install, tmp_path, home)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    assert (tmp_path / "pois.json").is_file()
    cache = home / ".cache" / "kinfu" / "numba"
    assert list(cache.rglob("zvc.*.nbi")), "the kernel was not cached there"
    # the warm-up looks for the kernels where they were cached
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(cache))
    assert list(warmup.cache_folder(read_only_install / "kinfu_cli" / "attention" / "zvc.py").glob("zvc.*.nbi"))


def test_a_read_only_install_without_a_writable_home_caches_under_the_temporary_folder(read_only_install,
                                                                                      tmp_path):
    home = tmp_path / "not-a-folder"
    home.touch()  # ~/.cache cannot be made: numba's own fall-back fails too
    res = run_zvc(read_only_install, tmp_path, home)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    assert (tmp_path / "pois.json").is_file()
    (folder,) = (tmp_path / "tmp").glob("kinfu-numba-*")
    assert list(folder.rglob("zvc.*.nbi")), "the kernel was not cached there"
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700  # the user's own


@pytest.fixture
def no_cache_anywhere(tmp_path, monkeypatch):
    """A package folder whose __pycache__ cannot be made, a home that is a file, and tmp_path/tmp as the
    temporary folder."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__pycache__").touch()
    (tmp_path / "home").touch()
    (tmp_path / "tmp").mkdir()
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    return pkg


def test_a_temporary_folder_others_can_write_is_not_used(no_cache_anywhere, tmp_path):
    """Someone made the user's folder beforehand, writable by all: numba would load their pickled code."""
    first = kinfu_cli._numba_cache_dir(str(no_cache_anywhere))
    assert first and Path(first).parent == tmp_path / "tmp"
    Path(first).chmod(0o777)
    second = kinfu_cli._numba_cache_dir(str(no_cache_anywhere))
    assert second and second != first and Path(second).parent == tmp_path / "tmp"
    assert stat.S_IMODE(Path(second).stat().st_mode) == 0o700


def test_the_cache_stays_beside_the_sources_when_it_can_or_the_user_chose(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert kinfu_cli._numba_cache_dir(str(tmp_path)) is None and (tmp_path / "__pycache__").is_dir()
    (tmp_path / "ro").mkdir()
    (tmp_path / "ro" / "__pycache__").touch()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "chosen"))
    assert kinfu_cli._numba_cache_dir(str(tmp_path / "ro")) is None


def test_a_runs_own_temporary_cache_is_removed_when_it_ends(read_only_install, tmp_path):
    """Someone else's folder at the user's name: the run compiles into a folder of its own, which it removes at
    exit (one was left behind per run before)."""
    import getpass

    home = tmp_path / "not-a-folder"
    home.touch()
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME")}
    tmp = tmp_path / "tmp"
    squatted = tmp / f"kinfu-numba-{getpass.getuser()}"
    squatted.mkdir(parents=True)
    squatted.chmod(0o777)
    env.update(PYTHONPATH=str(read_only_install), HOME=str(home), TMPDIR=str(tmp))
    res = subprocess.run([sys.executable, "-m", "kinfu_cli", "poi", str(SAMPLE / "tabletop" / "recording.mcap"),
                          "--algorithm", "zvc", "-o", "pois.json"], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    assert (tmp_path / "pois.json").is_file()
    assert sorted(p.name for p in tmp.iterdir()) == [squatted.name]
