"""`--scheduler` (and `--workers`) for commands whose trials may run on the Dask engine of `kinfu batch`."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import click

from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.trials import TrialMap


def scheduler_option(func):
    """`--scheduler tcp://HOST:PORT`: run the trials on that dask.distributed cluster."""
    return click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
                        help="Run the trials as tasks on this running dask.distributed scheduler (its workers must "
                             "see the same paths); the results are the same as in-process.")(func)


@contextlib.contextmanager
def trial_engine(scheduler: str | None, workers: int | None, *, desc: str, quiet: bool) -> Iterator[TrialMap | None]:
    """A trial map on the scheduler, or on a local cluster of `workers` processes, connected before any work
    (an unreachable scheduler is a one-line error); None (run in-process) when neither is given."""
    if scheduler is not None and workers is not None:
        raise ConfigError("--workers: sizes a local cluster; with --scheduler the cluster has its own workers")
    if scheduler is None and workers is None:
        yield None
        return
    from kinfu_cli.batch.engine import connect

    engine = connect(scheduler, workers)
    try:
        yield engine.trial_map(desc=desc, quiet=quiet)
    finally:
        engine.close()
