"""kinfu: offline robot spatial attention and next-best-view planning on recorded RGB-D data."""

import warnings

__version__ = "0.1.0"

# numba probes the TBB threading layer at its first parallel call and warns when the installed TBB
# is older than it wants; it then falls back to OpenMP/workqueue, which is what we want anyway.
warnings.filterwarnings("ignore", message="The TBB threading layer requires TBB version")
