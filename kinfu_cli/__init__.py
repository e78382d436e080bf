"""kinfu: offline robot spatial attention and next-best-view planning on recorded RGB-D data."""

import os as _os
import warnings as _warnings

__version__ = "0.1.0"

# numba's OpenMP threading layer busy-waits between parallel regions by default; on a machine with
# more busy processes than cores every short region then costs a scheduler time slice (~15 ms).
# It must be set before the first parallel numba loop, so it lives here, for every area.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# numba probes the TBB threading layer at its first parallel call and warns when the installed TBB
# is older than it wants; it then falls back to OpenMP/workqueue, which is what we want anyway.
_warnings.filterwarnings("ignore", message="The TBB threading layer requires TBB version")
