"""A warning about an option without effect (commands._options.check_inapplicable) goes first into the command's
result document as well as onto stderr before the work: a report read later says which options the run did not
use. Printed once: print_warnings leaves it out after the work."""

from __future__ import annotations

import json

from click.testing import CliRunner

from kinfu_cli.cli import cli
from tests.conftest import small_tabletop_volume


def _run(args):
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    return res


def _said_once(res, line):
    assert res.stderr.count(f"kinfu: warning: {line}") == 1, res.stderr


def test_poi_and_segment_and_diff_record_options_without_effect(sample_dir, tmp_path):
    rec = str(sample_dir / "recording.mcap")
    line = "--poi-threshold has no effect with --algorithm zvc (ignored)"
    res = _run(["poi", rec, "-o", str(tmp_path / "pois.json"), "--algorithm", "zvc", "--poi-threshold", "2", "--quiet"])
    _said_once(res, line)
    assert json.loads((tmp_path / "pois.json").read_text())["warnings"][0] == line

    vol = small_tabletop_volume()
    vol.save(tmp_path / "volume.npz")
    line = "--t-ff has no effect with --method lccp (ignored)"
    res = _run(["segment", str(tmp_path / "volume.npz"), "-o", str(tmp_path / "seg"), "--t-ff", "0.3", "--quiet",
                "--no-superquadrics"])
    _said_once(res, line)
    assert json.loads((tmp_path / "seg" / "segments.json").read_text())["warnings"][0] == line
    res = _run(["segment", str(tmp_path / "volume.npz"), "-o", str(tmp_path / "seg2"), "--t-ff", "0.3", "--json",
                "--quiet", "--no-superquadrics"])
    _said_once(res, line)
    assert json.loads(res.stdout)["warnings"][0] == line

    res = _run(["diff", str(tmp_path / "volume.npz"), str(tmp_path / "volume.npz"), "-o", str(tmp_path / "d"),
                "--match-radius", "0.3", "--quiet"])
    said = [w[len("kinfu: warning: "):] for w in res.stderr.splitlines() if "has no effect" in w]
    assert len(said) == 1, res.stderr
    assert json.loads((tmp_path / "d" / "changes.json").read_text())["warnings"][0] == said[0]


def test_fuse_report_records_options_without_effect(sample_dir, tmp_path):
    line = "--color has no effect with --no-color (ignored)"
    res = _run(["fuse", str(sample_dir / "recording.mcap"), "-o", str(tmp_path / "f"), "--no-color", "--color", "mean",
                "--voxel-size", "0.02", "--quiet", "--end", "1"])
    _said_once(res, line)
    assert json.loads((tmp_path / "f" / "report.json").read_text())["warnings"][0] == line
