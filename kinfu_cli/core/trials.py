"""How a driver runs independent trials: through a map function, so the caller chooses where they run.

A trial map is called as `map_trials(fn, items, shared)` and returns the results `fn(shared, item)` in the
order of `items` (an iterable: the serial map yields each as it is computed, so a caller can report progress). `fn` is a module-level function (it travels to other processes by reference), `shared` is
what every trial needs (sent once per process, not once per trial). `serial_trials` runs them here, one after
the other; `kinfu_cli.batch.engine.Engine.map_trials` runs them on a Dask cluster. A driver given no map runs
as before.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, Protocol


class TrialMap(Protocol):
    def __call__(self, fn: Callable[[Any, Any], Any], items: Sequence, shared: Any = None) -> Iterable: ...


def serial_trials(fn: Callable[[Any, Any], Any], items: Sequence, shared: Any = None) -> Iterator:
    """Every trial in this process, in order, each computed when the caller asks for it."""
    return (fn(shared, item) for item in items)
