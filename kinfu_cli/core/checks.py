"""Checks of numeric parameters: finite, inside a range, integral. One place for the wording of the error.

A NaN passes every `<`/`>` comparison as False, so `if x < 0: raise` lets it through; an inf or a 1e300
passes "positive" checks and overflows later. `check_number` refuses all three with a ConfigError naming
the parameter (the command line shows its flag).
"""

from __future__ import annotations

import math

from kinfu_cli.core.errors import ConfigError


def check_number(value, parameter: str, low: float | None = None, high: float | None = None, *,
                 low_open: bool = False, integer: bool = False, unit: str = "") -> float:
    """`value` as a float (an int when `integer`) when it is a finite number in the range [low, high]
    (`low_open`: (low, high]); else ConfigError naming `parameter`. None bounds are open ends."""
    ok = True
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        ok, v = False, math.nan
    ok = ok and not isinstance(value, bool) and math.isfinite(v)
    ok = ok and (low is None or (v > low if low_open else v >= low)) and (high is None or v <= high)
    ok = ok and (not integer or v.is_integer())
    if not ok:
        what = "an integer" if integer else "a finite number"
        lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}"
        hi = "" if high is None else f"<= {high:g}"
        rng = " and ".join(s for s in (lo, hi) if s)
        raise ConfigError(f"expected {what}{' ' + rng if rng else ''}{' ' + unit if unit else ''}, got {value!r}",
                          parameter=parameter)
    return int(v) if integer else v
