"""A terminal's Ctrl-C reaches the whole process group: the Dask worker processes kinfu starts must ignore it
(each printed a KeyboardInterrupt traceback under `kinfu: interrupted`), while kinfu itself still stops."""

from __future__ import annotations

import signal
import subprocess
import sys

from kinfu_cli.batch.engine import _workers_ignore_sigint

PROBE = "import signal; print(signal.getsignal(signal.SIGINT) is signal.SIG_IGN)"


def test_processes_started_for_the_cluster_ignore_sigint():
    before = signal.getsignal(signal.SIGINT)
    with _workers_ignore_sigint():  # what connect() starts its LocalCluster in (spawned workers inherit it)
        child = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True)
    assert child.stdout.strip() == "True"
    assert signal.getsignal(signal.SIGINT) is before  # this process still raises KeyboardInterrupt
    later = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True)
    assert later.stdout.strip() == "False"
