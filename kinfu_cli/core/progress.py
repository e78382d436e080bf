"""tqdm progress bars on stderr, off when asked (`quiet`) or when stderr is not a terminal (tqdm is then not
even imported: 30 ms of a short run)."""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import Any, TypeVar

T = TypeVar("T")


def progress_enabled(quiet: bool = False) -> bool:
    """True when a progress bar should be drawn."""
    return not quiet and sys.stderr.isatty()


def progress(iterable: Iterable[T], *, total: int | None = None, desc: str = "",
             quiet: bool = False, unit: str = "it") -> Iterable[T]:
    """Wrap an iterable in a tqdm bar on stderr (or return it unchanged when disabled)."""
    bar = _bar(quiet, iterable=iterable, total=total, desc=desc, unit=unit)
    return iterable if bar is None else bar


def progress_bar(total: int, *, desc: str = "", quiet: bool = False, unit: str = "it") -> Any | None:
    """A tqdm bar to update by hand (work that is not one loop), or None when progress is off."""
    return _bar(quiet, total=total, desc=desc, unit=unit)


def _bar(quiet: bool, **kwargs) -> Any | None:
    if not progress_enabled(quiet):
        return None
    from tqdm import tqdm

    return tqdm(file=sys.stderr, leave=False, dynamic_ncols=True, **kwargs)
