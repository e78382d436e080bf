"""kinfu: offline robot spatial attention and next-best-view planning on recorded RGB-D data."""

import os as _os
import sys as _sys
import warnings as _warnings

__version__ = "0.1.0"

# numba's OpenMP threading layer busy-waits between parallel regions by default; on a machine with
# more busy processes than cores every short region then costs a scheduler time slice (~15 ms).
# It must be set before the first parallel numba loop, so it lives here, for every area.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# The one place numba's threading layer is chosen, before any kinfu kernel compiles: the GNU OpenMP layer
# spins at every fork/join, and on a machine shared with other processes a descheduled spinning thread
# makes each small parallel kernel cost tens of milliseconds; numba's own workqueue pool does not spin.
# An explicit NUMBA_THREADING_LAYER wins. numba reads the variable at its import, so when numba is
# already imported (a notebook) its config is set instead.
if "NUMBA_THREADING_LAYER" not in _os.environ:
    if "numba" in _sys.modules:
        _sys.modules["numba"].config.THREADING_LAYER = "workqueue"
    else:
        _os.environ["NUMBA_THREADING_LAYER"] = "workqueue"


def _writable(folder: str) -> bool:
    """numba's own test of a cache folder (_CacheLocator.ensure_cache_path): create it, write a file in it."""
    import tempfile

    try:
        _os.makedirs(folder, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def _numba_cache_dir(package_dir: str) -> str | None:
    """Where numba caches kinfu's kernels when it cannot beside their sources (None: beside them, or the user chose).

    Every kernel is `@njit(cache=True)`; numba caches into the source's __pycache__, else ~/.cache/numba, and when
    neither can be written it raises at the kernel's import (a user who cannot write the install folder and has no
    writable home: a traceback). Then: $XDG_CACHE_HOME or ~/.cache, kinfu/numba; else a folder of this user's own
    under the temporary folder (one another user made beforehand is not trusted: numba loads pickled code).
    """
    import tempfile

    if _os.environ.get("NUMBA_CACHE_DIR") or _writable(_os.path.join(package_dir, "__pycache__")):
        return None
    xdg = _os.environ.get("XDG_CACHE_HOME", "")
    base = xdg if _os.path.isabs(xdg) else _os.path.join(_os.path.expanduser("~"), ".cache")
    if _os.path.isabs(base) and _writable(folder := _os.path.join(base, "kinfu", "numba")):
        return folder
    uid = _os.getuid() if hasattr(_os, "getuid") else None
    try:
        import getpass

        user = getpass.getuser()
    except Exception:  # noqa: BLE001 - no login name (a uid without a passwd entry): the uid names the folder
        user = str(uid)
    try:
        folder = _os.path.join(tempfile.gettempdir(), f"kinfu-numba-{user}")
        _os.makedirs(folder, mode=0o700, exist_ok=True)
        st = _os.stat(folder)
        if (uid is None or st.st_uid == uid) and not st.st_mode & 0o022 and _writable(folder):
            return folder
        own = tempfile.mkdtemp(prefix=f"kinfu-numba-{user}-")  # this run's own; compiled again by the next
        import atexit
        import shutil

        atexit.register(shutil.rmtree, own, True)  # one per run: left behind, they piled up in the temporary folder
        return own
    except OSError:  # no writable temporary folder either: numba says so itself
        return None


if _cache_dir := _numba_cache_dir(_os.path.dirname(_os.path.abspath(__file__))):
    _os.environ["NUMBA_CACHE_DIR"] = _cache_dir
    if "numba" in _sys.modules:  # numba read its config at import (a notebook): set it there too
        _sys.modules["numba"].config.CACHE_DIR = _cache_dir

# numba probes the TBB threading layer at its first parallel call and warns when the installed TBB
# is older than it wants; it then falls back to OpenMP/workqueue, which is what we want anyway.
_warnings.filterwarnings("ignore", message="The TBB threading layer requires TBB version")
