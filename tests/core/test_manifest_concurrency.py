"""Runs writing into one folder at the same time keep each other's manifest entries (the manifest is read,
changed and replaced under the folder's lock): 4 processes writing 60 files each left 102 of the 240 recorded,
and the next run refused the other files as not kinfu's."""

from __future__ import annotations

import multiprocessing as mp
import subprocess
import sys
from pathlib import Path

from kinfu_cli.core.atomic import atomic_path
from kinfu_cli.core.ownership import manifest_files, written_by_kinfu

N_FILES = 40


def _write_files(folder: str, tag: str) -> None:
    for i in range(N_FILES):
        with atomic_path(Path(folder) / f"{tag}_{i}.json") as tmp:
            tmp.write_text(tag)


def test_concurrent_writers_keep_every_entry(tmp_path):
    ctx = mp.get_context("fork")
    procs = [ctx.Process(target=_write_files, args=(str(tmp_path), tag)) for tag in "abcd"]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    assert [p.exitcode for p in procs] == [0, 0, 0, 0]
    files = manifest_files(tmp_path)
    assert len(files) == 4 * N_FILES
    assert all(written_by_kinfu(tmp_path / name) for name in files)


def test_a_folder_output_with_files_written_inside_does_not_wait_on_its_own_lock(tmp_path):
    """atomic_dir holds its temporary's lock while the caller writes into it; the manifest update of a file
    written there takes the same lock in the same process (flock would wait on itself forever)."""
    code = ("import sys; from pathlib import Path; from kinfu_cli.core.atomic import atomic_dir, atomic_path\n"
            "with atomic_dir(Path(sys.argv[1]) / 'out') as d:\n"
            "    with atomic_path(d / 'a.json') as t:\n"
            "        t.write_text('{}')\n")
    res = subprocess.run([sys.executable, "-c", code, str(tmp_path)], timeout=60, capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[2])
    assert res.returncode == 0, res.stderr
    assert written_by_kinfu(tmp_path / "out") and written_by_kinfu(tmp_path / "out" / "a.json")


def test_threads_of_one_process_keep_every_entry(tmp_path):
    """Dask's threads in one worker process: the lock is re-entrant per thread, not per process."""
    import threading

    threads = [threading.Thread(target=_write_files, args=(str(tmp_path), tag)) for tag in "abcd"]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert len(manifest_files(tmp_path)) == 4 * N_FILES
