"""Next-best-view: candidate viewpoints, ray casting through the ternary map, gains."""

import os as _os

# numba's OpenMP threading layer busy-waits between parallel regions by default; on a machine with
# more busy processes than cores every short region then costs a scheduler time slice (~15 ms).
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
