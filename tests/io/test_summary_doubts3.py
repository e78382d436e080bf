"""`kinfu info` on a ROS 2 bag folder takes its time span from the storage, not from metadata.yaml."""

from __future__ import annotations

import json
import shutil

from click.testing import CliRunner

from kinfu_cli.cli import cli
from kinfu_cli.io.summary import recording_summary

START_NS = 1767225600000000000  # the sample's first stamp (2026-01-01 00:00:00 UTC), 15.24 s long


def test_ros2_time_span_comes_from_the_storage_not_metadata_yaml(sample_dir, tmp_path):
    bag = tmp_path / "bag"
    shutil.copytree(sample_dir / "recording_ros2", bag)
    meta = bag / "metadata.yaml"
    text = meta.read_text()
    assert f"nanoseconds_since_epoch: {START_NS}" in text and "nanoseconds: 15240000000" in text
    meta.write_text(text.replace(f"nanoseconds_since_epoch: {START_NS}", "nanoseconds_since_epoch: 1000000000000000000")
                    .replace("nanoseconds: 15240000000", "nanoseconds: 99000000000"))
    res = CliRunner().invoke(cli, ["info", str(bag), "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["start_ns"] == START_NS
    assert abs(doc["duration_s"] - 15.24) < 1e-6
    said = [p for p in doc["problems"] if "time span" in p]
    assert len(said) == 1 and "metadata.yaml" in said[0] and "(99.000 s) listed" in said[0]
    assert "15.240 s) stored" in said[0]
    text_out = CliRunner().invoke(cli, ["info", str(bag)]).output
    assert "time span: 2026-01-01 00:00:00.000 UTC .. 2026-01-01 00:00:15.240 UTC (15.240 s)" in text_out


def test_ros2_span_that_agrees_says_nothing(sample_dir):
    s = recording_summary(sample_dir / "recording_ros2")
    assert s["start_ns"] == START_NS and abs(s["duration_s"] - 15.24) < 1e-6
    assert not [p for p in s["problems"] if "time span" in p]
