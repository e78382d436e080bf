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

# numba probes the TBB threading layer at its first parallel call and warns when the installed TBB
# is older than it wants; it then falls back to OpenMP/workqueue, which is what we want anyway.
_warnings.filterwarnings("ignore", message="The TBB threading layer requires TBB version")
