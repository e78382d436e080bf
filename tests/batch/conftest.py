"""The Dask cluster the batch and eval-scheduler tests submit to."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def scheduler():
    """The address of a 2-worker LocalCluster (processes, one thread each), like a lab's cluster; its dashboard
    on a free port (the default 8787 may be taken by another run: a warning)."""
    from dask.distributed import LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=50)
    yield cluster.scheduler_address
    cluster.close()
