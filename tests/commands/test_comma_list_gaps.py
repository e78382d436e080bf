"""Comma-list options that skipped an empty item ('a,,b', a trailing comma, ',') or read an empty value as the
default ran with exit 0 (eval grasp --scenes ',' scored 0 scenes, eval poi --speed '' ran speed 1), where the
other list options refuse them. Every comma-list option now goes through commands/_options.comma_items /
comma_values: one `kinfu: error:` line naming the option, exit 2, before any work."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.conftest import one_line_error

GAP = "an empty item; expected comma-separated values without gaps"
EMPTY = "expected a value, got an empty one"


@pytest.mark.parametrize("args, option, said", [
    (["localize", "--models", "a.ply,,", "p.txt"], "--models", GAP),
    (["eval", "grasp", "--scenes", ","], "--scenes", GAP),
    (["eval", "grasp", "--conditions", "none,,top"], "--conditions", GAP),
    (["eval", "grasp", "--conditions", ""], "--conditions", EMPTY),
    (["eval", "nbv", "{tmp}", "--strategy", "poi,,random"], "--strategy", GAP),
    (["eval", "nbv", "{tmp}", "--strategy", ""], "--strategy", EMPTY),
    (["eval", "localize", "--shapes", "box,,box"], "--shapes", GAP),
    (["eval", "localize", "--methods", "mupf,,"], "--methods", GAP),
    (["eval", "localize", "--methods", ""], "--methods", EMPTY),
    (["eval", "segment", "--sweep", "--color", "mean,,mode"], "--color", GAP),
    (["eval", "segment", "--sweep", "--scene", "objects,"], "--scene", GAP),
    (["eval", "poi", "{tmp}", "--speed", ""], "--speed", EMPTY),
    (["eval", "poi", "{tmp}", "--speed", "1,,2"], "--speed", GAP),
    (["eval", "poi", "{tmp}", "--noise", "0.01,"], "--noise", GAP),
])
def test_an_empty_item_or_value_of_a_list_option_is_refused(tmp_path, args, option, said):
    out = tmp_path / "out.json"
    write = [] if args[:2] == ["eval", "poi"] else ["-o", str(out)]  # eval poi prints only
    res = CliRunner().invoke(cli, [a.format(tmp=tmp_path) for a in args] + write + ["--quiet"])
    one_line_error(res, option, said)
    assert not out.exists()


def test_eval_grasp_scenes_blank_still_means_none(tmp_path):
    """--scenes '' is documented as "none" (the generated objects only): still accepted."""
    out = tmp_path / "g.json"
    res = CliRunner().invoke(cli, ["eval", "grasp", "--conditions", "none", "--yaws", "1", "--scenes", "", "-o",
                                   str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    assert out.is_file()
