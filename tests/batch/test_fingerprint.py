"""When a stage counts as current: same inputs (size + mtime), same options, outputs unchanged."""

from __future__ import annotations

import os
import shutil

from kinfu_cli.batch.fingerprint import input_fingerprint, output_stats


def test_fingerprint_follows_inputs_and_options_not_locations(tmp_path):
    rec = tmp_path / "a" / "rec.mcap"
    rec.parent.mkdir()
    rec.write_bytes(b"12345")
    os.utime(rec, ns=(10**18, 10**18))
    fp = input_fingerprint("fuse", [("<recording>", rec)], {"voxel-size": 0.02})
    assert fp == input_fingerprint("fuse", [("<recording>", rec)], {"voxel-size": 0.02})
    assert fp != input_fingerprint("fuse", [("<recording>", rec)], {"voxel-size": 0.01})
    assert fp != input_fingerprint("segment", [("<recording>", rec)], {"voxel-size": 0.02})
    # moved or copied whole with its times: still current; touched or rewritten: not
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    assert fp == input_fingerprint("fuse", [("<recording>", tmp_path / "b" / "rec.mcap")], {"voxel-size": 0.02})
    os.utime(rec, ns=(10**18, 10**18 + 1))
    assert fp != input_fingerprint("fuse", [("<recording>", rec)], {"voxel-size": 0.02})


def test_fingerprint_of_a_folder_recording_covers_its_files(tmp_path):
    bag = tmp_path / "ros2"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("a")
    (bag / "ros2_0.db3").write_bytes(b"x" * 10)
    fp = input_fingerprint("poi", [("<recording>", bag)], {})
    (bag / "ros2_0.db3").write_bytes(b"x" * 11)
    assert fp != input_fingerprint("poi", [("<recording>", bag)], {})


def test_output_stats_none_when_an_output_is_missing(tmp_path):
    (tmp_path / "fuse").mkdir()
    (tmp_path / "fuse" / "volume.npz").write_bytes(b"v")
    assert output_stats(tmp_path, ["fuse/volume.npz"])["fuse/volume.npz"][0] == 1
    assert output_stats(tmp_path, ["fuse/volume.npz", "fuse/report.json"]) is None
