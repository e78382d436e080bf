"""A terminal's Ctrl-C reaches the whole process group: the Dask worker processes kinfu starts must not take it
(each printed a KeyboardInterrupt traceback under `kinfu: interrupted`), while kinfu itself still stops."""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from kinfu_cli.batch.engine import _started_deaf_to_sigint

PROBE = "import signal; print(signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, []))"

pytestmark = pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="no POSIX signal masks")


def test_processes_started_for_the_cluster_do_not_take_sigint():
    def start():  # what connect() starts its LocalCluster in (the workers inherit the blocked signal)
        return subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True).stdout

    assert _started_deaf_to_sigint(start).strip() == "True"
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])  # this thread still takes Ctrl-C
    later = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True)
    assert later.stdout.strip() == "False"
