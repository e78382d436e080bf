"""kinfu synth writes its folder in one transaction: an interrupted run left an empty (or half-written) OUT that
then blocked the rerun as "an existing folder that kinfu did not write"; a rerun into another kinfu output
folder mixed the two results."""

from __future__ import annotations

import pytest

from kinfu_cli.sim import synth


def test_an_interrupted_synth_leaves_no_folder(tmp_path, monkeypatch):
    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(synth, "write_ground_truth", stop)
    with pytest.raises(KeyboardInterrupt):
        synth.synthesize(tmp_path / "out", frames=3, formats=("mcap",))
    assert list(tmp_path.iterdir()) == []


def test_a_rerun_replaces_the_earlier_result_whole(tmp_path):
    out = tmp_path / "out"
    first = synth.synthesize(out, frames=3, formats=("mcap", "bag"))
    assert first.recordings == [out / "recording.mcap", out / "recording.bag"] and first.ground_truth.is_dir()
    (out / "mine.txt").write_text("user")
    synth.synthesize(out, frames=3, formats=("mcap",))
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["ground_truth", "mine.txt",
                                                                                    "recording.mcap"]
