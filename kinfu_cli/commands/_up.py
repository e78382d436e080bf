"""The `--up` option value of fuse, import and segment: x,y,z (checked by core.grid.check_up) or a keyword."""

from __future__ import annotations

import numpy as np

from kinfu_cli.commands._options import comma_items
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.grid import check_up


def parse_up(value: str | None, keywords: tuple[str, ...] = ()) -> np.ndarray | str | None:
    """None for None, a keyword of `keywords` (lower case) as itself, else the unit vector of 'x,y,z';
    ConfigError naming parameter 'up' for anything else (NaN, inf and zero vectors included)."""
    if value is None:
        return None
    v = value.strip().lower()
    if v in keywords:
        return v
    try:
        xyz = [float(x) for x in comma_items(v, "--up")]  # an empty item ('0,,1'): the list options' error
    except ValueError:
        xyz = []
    if len(xyz) != 3:
        also = "".join(f" or '{k}'" for k in keywords)
        raise ConfigError(f"expected 'x,y,z'{also}, got {value!r}", parameter="up")
    return check_up(xyz, "up")
