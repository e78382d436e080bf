"""--force reaches the folder writers of export, synth and import (a ROS 2 bag folder): a kinfu file the user
edited since is refused before the work without it, and replaced with it (it was refused after the work even
with --force)."""

from __future__ import annotations

from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli


def _run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_force_replaces_an_edited_kinfu_file_in_export_synth_and_import_folders(tmp_path):
    synth = ("synth", "--width", 32, "--height", 24, "--frames", 4, "--formats", "mcap", "-q")
    assert _run(*synth, "-o", tmp_path / "s").exit_code == 0
    edited = tmp_path / "s" / "ground_truth" / "changes.json"
    edited.write_text(edited.read_text() + " ")
    one_line_error(_run(*synth, "-o", tmp_path / "s"), "changed since kinfu wrote them", "--force")
    assert _run(*synth, "-o", tmp_path / "s", "--force").exit_code == 0
    rec = tmp_path / "s" / "recording.mcap"
    export = ("export", rec, "-o", tmp_path / "fx", "-q")
    assert _run(*export).exit_code == 0
    (tmp_path / "fx" / "frames.json").write_text("{}")
    one_line_error(_run(*export), "fx/frames.json", "--force")
    res = _run(*export, "--force")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "fx" / "frames.json").read_text() != "{}"
    imp = ("import", tmp_path / "fx", "-o", tmp_path / "bx", "-q")
    assert _run(*imp).exit_code == 0
    (tmp_path / "bx" / "metadata.yaml").write_text((tmp_path / "bx" / "metadata.yaml").read_text() + "\n")
    one_line_error(_run(*imp), "bx/metadata.yaml", "--force")
    res = _run(*imp, "--force")
    assert res.exit_code == 0, res.output
