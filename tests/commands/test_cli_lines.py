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



@pytest.mark.parametrize("command, advice", [("fuse", " (try a coarser --voxel-size or a smaller --size)"),
                                             ("info", "")])
def test_out_of_memory_is_one_line_advising_only_options_the_command_has(monkeypatch, command, advice):
    """An nbv or info run out of memory was told to try --voxel-size / --size, options it does not have."""
    import click

    real = cli.get_command(click.Context(cli), command)

    def no_memory(**kwargs):
        raise MemoryError

    fake = click.Command(command, params=real.params, callback=no_memory)
    monkeypatch.setattr(type(cli), "get_command", lambda self, ctx, name: fake if name == command else None)
    res = CliRunner().invoke(cli, [command, "x.mcap"] + (["-o", "out"] if command == "fuse" else []))
    assert res.exit_code == 2 and res.output == f"kinfu: error: out of memory{advice}\n", res.output


def test_a_reader_meeting_the_end_of_a_cut_file_is_an_error_not_an_interrupt(monkeypatch):
    """An EOFError (np.load of an empty file, a reader at the end of a cut one) was reported as Ctrl-C."""
    import click

    real = cli.get_command(click.Context(cli), "info")

    def cut_short(**kwargs):
        raise EOFError("No data left in file")

    fake = click.Command("info", params=real.params, callback=cut_short)
    monkeypatch.setattr(type(cli), "get_command", lambda self, ctx, name: fake if name == "info" else None)
    res = CliRunner().invoke(cli, ["info", "x.mcap"])
    assert res.exit_code == 2
    assert res.output == "kinfu: error: an input file ends early, it may be truncated (No data left in file)\n"
