"""The Dask cluster the batch and eval-scheduler tests submit to, and a spy for the tests that must never reach it."""

from __future__ import annotations

import pytest

from kinfu_cli.core.errors import KinfuError


@pytest.fixture(scope="session")
def scheduler():
    """The address of a 2-worker LocalCluster (processes, one thread each), like a lab's cluster; its dashboard
    on a free port (the default 8787 may be taken by another run: a warning)."""
    from dask.distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=50)
    yield cluster.scheduler_address
    cluster.close()


class Connected(KinfuError):
    """Raised by the spy standing in for the Dask connection: the run got past every check."""


@pytest.fixture
def connects(monkeypatch) -> list:
    """Calls of batch's cluster connection (none may happen for bad input); a call ends the run with exit 2."""
    calls: list = []

    def spy(*args, **kwargs):
        calls.append(args)
        raise Connected("connected to a cluster")

    monkeypatch.setattr("kinfu_cli.commands.batch.connect", spy)
    return calls


@pytest.fixture
def quick_refusal(monkeypatch):
    """An unreachable scheduler refused after 0.5 s instead of batch.engine's 5 (tests wait for a closed port,
    which no wait would open)."""
    monkeypatch.setattr("kinfu_cli.batch.engine.CONNECT_TIMEOUT_S", 0.5)
