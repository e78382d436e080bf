"""The CLI skeleton: help, version, one-line errors."""

import click
from click.testing import CliRunner

from kinfu_cli.cli import cli


def test_help_lists_commands_with_descriptions():
    res = CliRunner().invoke(cli, ["--help"])
    assert res.exit_code == 0
    assert "Usage:" in res.output
    for name in cli.list_commands(None):
        cmd = cli.get_command(None, name)
        assert name in res.output
        assert cmd.get_short_help_str(), f"{name} has no one-line description"


def test_each_subcommand_help_shows_an_example():
    for name in cli.list_commands(None):
        cmd = cli.get_command(None, name)
        subs = cmd.list_commands(None) if isinstance(cmd, click.Group) else [None]
        for sub in subs:
            args = [name] + ([sub] if sub else []) + ["--help"]
            res = CliRunner().invoke(cli, args)
            assert res.exit_code == 0, args
            assert "Example" in res.output, f"`kinfu {' '.join(args)}` shows no example"


def test_unknown_command_is_a_usage_error():
    res = CliRunner().invoke(cli, ["no-such-command"])
    assert res.exit_code == 2
