"""`kinfu --help` lists every command from cli.SUMMARIES without importing the stages."""

from __future__ import annotations

import importlib
import subprocess
import sys

from kinfu_cli.cli import COMMANDS, SUMMARIES


def _modules():
    for name, target in COMMANDS.items():
        if isinstance(target, dict):
            for sub, module in target.items():
                yield f"{name} {sub}", module
        else:
            yield name, target


def test_summaries_are_the_commands_own_first_help_lines():
    for name, module in _modules():
        cmd = importlib.import_module(f"kinfu_cli.commands.{module}").command
        assert SUMMARIES[name] == cmd.get_short_help_str(1000), name
    assert set(SUMMARIES) == {n for n, _ in _modules()} | {"eval"}


def test_help_lists_every_command_without_importing_a_stage():
    code = ("import sys\nfrom kinfu_cli.cli import cli\ncli.main(['--help'], standalone_mode=False)\n"
            "print('LOADED', sorted(m for m in sys.modules if m.startswith('kinfu_cli.commands.')"
            " and not m.startswith('kinfu_cli.commands._')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "LOADED []" in out
    for name in COMMANDS:
        assert f"  {name} " in out, name
    assert "Grasp poses for segmented objects" in out
