"""Checked before any work, as the other option values: a plan's fuse window (start / end: NaN, a start after
the end or a negative end passed the check, each recording then failed in its Dask task, exit 1), and a user's
file where a stage writes (named with the plan entry and stage, not as batch's --output)."""

from __future__ import annotations

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.core.errors import KinfuError


class Connected(KinfuError):
    """Raised by the spy standing in for the Dask connection: the run got past every check."""


@pytest.fixture
def connects(monkeypatch) -> list:
    calls: list = []

    def spy(*args, **kwargs):
        calls.append(args)
        raise Connected("connected to a cluster")

    monkeypatch.setattr("kinfu_cli.commands.batch.connect", spy)
    return calls


@pytest.mark.parametrize("line, needle", [
    ("start = nan", "fuse: start: expected a finite number of seconds"),
    ("end = inf", "fuse: end: expected a finite number of seconds"),
    ("start = 5\nend = 1", "fuse: start/end: start 5.0 s is after end 1.0 s"),
    ("end = -3", "fuse: end: end -3 s is before the recording's start"),
])
def test_bad_window_is_refused_before_any_work(tmp_path, connects, line, needle):
    (tmp_path / "a.mcap").touch()  # empty: nothing may be read before the options are checked
    plan = tmp_path / "plan.toml"
    plan.write_text(f'output = "out"\nstages = ["fuse"]\nrecordings = ["a.mcap"]\n[options.fuse]\n{line}\n')
    res = CliRunner().invoke(cli, ["batch", str(plan), "--quiet"], catch_exceptions=False)
    one_line_error(res, f"{plan}: recordings[0] {tmp_path / 'a.mcap'}: {needle}")
    assert connects == [] and not (tmp_path / "out").exists()


def test_a_good_window_gets_to_the_cluster(tmp_path, connects):
    (tmp_path / "a.mcap").touch()
    plan = tmp_path / "plan.toml"
    plan.write_text('output = "out"\nstages = ["fuse"]\nrecordings = ["a.mcap"]\n[options.fuse]\nstart = -1\n'
                    'end = 2.5\n')
    one_line_error(CliRunner().invoke(cli, ["batch", str(plan), "--quiet"], catch_exceptions=False),
                   "connected to a cluster")


def test_a_users_file_where_a_stage_writes_is_named_with_its_plan_entry(tmp_path, connects):
    """It was reported as `--output: .../pois.json: ...`, as if batch's -o were at fault."""
    (tmp_path / "a.mcap").touch()
    (tmp_path / "out" / "a").mkdir(parents=True)
    (tmp_path / "out" / "a" / "pois.json").write_text('{"mine": 1}')
    plan = tmp_path / "plan.toml"
    plan.write_text('output = "out"\nstages = ["poi"]\nrecordings = ["a.mcap"]\n')
    line = one_line_error(CliRunner().invoke(cli, ["batch", str(plan), "--quiet"], catch_exceptions=False),
                          f"{plan}: recordings[0] {tmp_path / 'a.mcap'}: poi: {tmp_path / 'out/a/pois.json'}",
                          "kinfu did not write", "--force")
    assert "--output" not in line and connects == []
    assert (tmp_path / "out" / "a" / "pois.json").read_text() == '{"mine": 1}'
