"""One `kinfu batch` at a time per output folder.

Two runs on one folder would interleave their stages' writes and each rewrite manifest.json from its own view.
The lock is an advisory `flock` on OUTPUT/.kinfu-batch.lock, taken before any work and held until the run ends;
the kernel drops it when the process dies, so a killed run leaves no stale lock (the file stays, holding the
last holder's pid for the message). A folder the run created is removed again when nothing was written into it,
and a lock file the run created is removed again when the run fails (e.g. refused before any work), so a refused
run leaves nothing in a user's folder. Batch runs on other machines sharing the folder over NFS are not covered: flock is local there.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from pathlib import Path

from kinfu_cli.core.errors import ConfigError, KinfuError

LOCK_NAME = ".kinfu-batch.lock"
_MARK = "kinfu batch lock"


@contextlib.contextmanager
def batch_lock(output: str | os.PathLike, named: Callable[[KinfuError], KinfuError] | None = None) -> Iterator[Path]:
    """Hold the output folder's batch lock (created with the folder when missing); ConfigError naming the lock
    file and its holder when another run holds it, or when a file of that name is not kinfu's. An error about the
    folder itself names the `output` parameter, or goes through `named` (Plan.output_error: the plan's key)."""
    named = named or (lambda exc: exc)
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield Path(output) / LOCK_NAME
        return
    folder = Path(output)
    if folder.exists() and not folder.is_dir():
        raise named(ConfigError(f"{folder}: exists and is not a folder", parameter="output"))
    created = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / LOCK_NAME
        lock_existed = path.exists()
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise named(ConfigError(f"{folder}: cannot create the batch lock ({exc.strerror})",
                                parameter="output")) from None
    failed, locked = True, False
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip().removeprefix(_MARK).strip()
            raise ConfigError(f"{path}: another kinfu batch is writing to {folder} ({holder or 'a running process'}); "
                              "wait for it to end") from None
        text = os.pread(fd, 200, 0).decode(errors="replace")
        if text and not text.startswith(_MARK):
            raise ConfigError(f"{path}: exists and was not written by kinfu; move it away")
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{_MARK} pid {os.getpid()}\n".encode(), 0)
        locked = True
        yield path
        failed = False
    finally:
        if created and [p.name for p in folder.iterdir()] == [LOCK_NAME]:  # nothing ran: leave no trace
            with contextlib.suppress(OSError):
                path.unlink()
                folder.rmdir()
        elif failed and locked and not lock_existed:  # ours, from a run that failed: not left behind
            with contextlib.suppress(OSError):
                path.unlink()
        os.close(fd)  # releases the lock
