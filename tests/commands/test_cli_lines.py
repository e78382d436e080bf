"""Every way a run can end badly is one line on stderr: usage errors, bad option values, Ctrl-C."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("args, line", [
    (["fuse", "x.mcap", "-o", "o", "--fill-gaps", "-1"], "kinfu: error: --fill-gaps: -1 is not in the range x>=0."),
    (["fuse", "x.mcap"], "kinfu: error: Missing option '-o' / '--output'."),
    (["nbv", "v.npz", "--bogus"], "kinfu: error: No such option '--bogus'."),
    (["no-such-command"], "kinfu: error: No such command 'no-such-command'."),
])
def test_usage_errors_are_one_line_without_a_usage_block(args, line):
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 2
    assert len(res.output.strip().splitlines()) == 1 and res.output.startswith(line), res.output


def test_a_newline_in_a_message_does_not_split_the_line(tmp_path):
    bad = tmp_path / "a\nb.mcap"
    res = CliRunner().invoke(cli, ["info", str(bad)])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1, res.output
    assert "a\\nb.mcap" in res.output


def _default_sigint() -> None:
    """A test runner's worker may ignore SIGINT, and an ignored signal stays ignored across exec (Python then
    installs no KeyboardInterrupt handler): give the child the default disposition a terminal gives."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_is_one_line_and_exit_130(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-m", "kinfu_cli", "fuse", str(REPO / "sample_data/tabletop/recording.mcap"),
                             "-o", str(tmp_path / "out"), "--quiet"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=_default_sigint)
    time.sleep(2.5)  # inside start-up imports or the fusion itself; both must end the same way
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err == "kinfu: interrupted\n"
    assert not (tmp_path / "out").exists()
    assert [p.name for p in tmp_path.iterdir()] == []  # no debris either
