"""synth, import and export with --quiet printed their 'wrote ...' summaries all the same; like the other commands
they now print only warnings and errors (--json still prints the JSON)."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli


def _run(*args):
    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


def test_synth_import_and_export_are_silent_with_quiet(tmp_path):
    tiny = ["--width", "64", "--height", "48", "--frames", "4", "--formats", "mcap"]
    assert "wrote" in _run("synth", "-o", tmp_path / "loud", *tiny).stdout
    assert _run("synth", "-o", tmp_path / "s", *tiny, "-q").stdout == ""
    rec = next((tmp_path / "s").glob("*.mcap"))
    assert "wrote" in _run("export", rec, "-o", tmp_path / "e_loud").stdout
    assert _run("export", rec, "-o", tmp_path / "e", "-q").stdout == ""
    assert _run("export", rec, "-o", tmp_path / "t.tum", "--trajectory", "tum", "-q").stdout == ""
    assert "wrote" in _run("import", tmp_path / "e", "-o", tmp_path / "loud.mcap").stdout
    assert _run("import", tmp_path / "e", "-o", tmp_path / "again.mcap", "-q").stdout == ""
    doc = json.loads(_run("export", rec, "-o", tmp_path / "e2", "-q", "--json").stdout)
    assert doc["frames"] > 0
