"""Output safety: kinfu replaces only what it wrote, never an input or a user's file, and a folder output
appears whole or not at all."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.errors import KinfuError
from kinfu_cli.core.ownership import MANIFEST, ForeignOutputError, claim_output, written_by_kinfu


def test_written_files_are_recorded_and_lose_ownership_when_changed(tmp_path):
    out = write_json(tmp_path / "a.json", {"x": 1})
    assert written_by_kinfu(out)
    assert claim_output(out) == out  # kinfu may replace its own file
    out.write_text('{"x": 2, "edited": "by the user"}')
    assert not written_by_kinfu(out)
    with pytest.raises(ForeignOutputError, match="kinfu did not write"):
        claim_output(out)
    assert claim_output(out, force=True) == out


def test_empty_input_and_enclosing_outputs_are_always_refused(tmp_path):
    rec = tmp_path / "data" / "rec.mcap"
    rec.parent.mkdir()
    rec.write_bytes(b"x")
    for bad in ("", "  ", None):
        with pytest.raises(KinfuError, match="empty"):
            claim_output(bad, force=True)
    with pytest.raises(KinfuError, match="is also an input"):
        claim_output(rec, [rec], force=True)
    with pytest.raises(KinfuError, match="contains the input"):
        claim_output(tmp_path / "data", [rec], force=True)
    with pytest.raises(KinfuError, match="contains the input"):
        claim_output(tmp_path, [rec], force=True)
    os.symlink(rec, tmp_path / "link.mcap")
    with pytest.raises(KinfuError, match="is also an input"):
        claim_output(tmp_path / "link.mcap", [rec], force=True)


def test_an_existing_user_folder_is_refused_and_kinfu_folders_are_not(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "thesis.tex").write_text("precious")
    with pytest.raises(ForeignOutputError, match="existing folder"):
        claim_output(user)
    with atomic_dir(tmp_path / "out") as d:
        write_json(d / "report.json", {})
    assert (tmp_path / "out" / MANIFEST).is_file() and written_by_kinfu(tmp_path / "out")
    claim_output(tmp_path / "out")


def test_replacing_a_folder_keeps_user_files_and_drops_old_outputs(tmp_path):
    out = tmp_path / "out"
    with atomic_dir(out) as d:
        write_json(d / "old.json", {"v": 1})
        write_json(d / "report.json", {"v": 1})
    (out / "notes.txt").write_text("mine")
    with atomic_dir(out) as d:
        write_json(d / "report.json", {"v": 2})
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST, "notes.txt", "report.json"]
    assert (out / "notes.txt").read_text() == "mine"
    assert [p.name for p in tmp_path.iterdir() if p.name != MANIFEST] == ["out"]  # no debris left


def test_a_failed_run_leaves_the_old_folder_untouched_and_debris_is_cleaned(tmp_path):
    out = tmp_path / "out"
    with atomic_dir(out) as d:
        write_json(d / "report.json", {"v": 1})
    with pytest.raises(RuntimeError):
        with atomic_dir(out) as d:
            write_json(d / "report.json", {"v": 2})
            raise RuntimeError("killed")
    assert (out / "report.json").read_text().count('"v": 1') == 1
    stale = tmp_path / ".out.k1ll3d00.part"  # what a SIGKILLed run leaves (mkdtemp: 8 random characters)
    stale.mkdir()
    (stale / "mesh.ply").write_text("half")
    with atomic_dir(out) as d:
        write_json(d / "report.json", {"v": 3})
    assert not stale.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST, "out"]


def test_debris_cleaning_touches_only_kinfus_temporary_names(tmp_path):
    (tmp_path / ".report.notes.part.json").write_text("a user's file that merely looks like a temporary")
    (tmp_path / ".report.ab12cd34.part.json").write_text("half-written by a killed run")
    write_json(tmp_path / "report.json", {})
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [MANIFEST, ".report.notes.part.json", "report.json"]


def test_a_users_file_inside_a_kinfu_subfolder_survives_a_rerun_and_stale_outputs_do_not(tmp_path):
    import numpy as np  # the subfolder's files come from a writer that knows nothing of manifests

    out = tmp_path / "out"
    with atomic_dir(out) as d:
        (d / "regions").mkdir()
        for i in range(3):
            np.save(d / "regions" / f"{i}.npy", np.zeros(i + 1))
        write_json(d / "report.json", {"v": 1})
    (out / "regions" / "my_notes.txt").write_text("mine")
    with atomic_dir(out) as d:
        (d / "regions").mkdir()
        np.save(d / "regions" / "0.npy", np.ones(2))
        write_json(d / "report.json", {"v": 2})
    assert sorted(p.name for p in (out / "regions").iterdir() if p.name != MANIFEST) == ["0.npy", "my_notes.txt"]
    assert (out / "regions" / "my_notes.txt").read_text() == "mine"
    assert np.load(out / "regions" / "0.npy").tolist() == [1.0, 1.0]  # the new output, not the old one
    (out / "regions" / "my_notes.txt").unlink()
    (out / "regions" / "0.npy").unlink()
    (out / "regions" / "0.npy").write_text("the user's own file now, under an output's name")
    with pytest.raises(KinfuError, match="regions/0.npy there was not written by kinfu"):
        with atomic_dir(out) as d:
            (d / "regions").mkdir()
            np.save(d / "regions" / "0.npy", np.ones(2))
    assert (out / "regions" / "0.npy").read_text().startswith("the user's")


def test_the_manifest_has_the_outputs_mode(tmp_path):
    """The manifest was 0600 (mkstemp's mode) beside 0644 outputs: a colleague's run, able to read the outputs,
    could not read the record and took them for a user's files."""
    mask = os.umask(0o022)
    try:
        out = write_json(tmp_path / "a.json", {"x": 1})
    finally:
        os.umask(mask)
    assert (out.stat().st_mode & 0o777) == ((tmp_path / MANIFEST).stat().st_mode & 0o777) == 0o644


def test_a_file_of_a_folder_output_is_not_replaced_alone_and_outputs_do_not_nest(tmp_path):
    # grasp --plot seg/segments.ply replaced segment's cloud with a PNG; segment -o seg --viz seg/segments.json
    # replaced its own result with an MCAP; both exited 0
    from kinfu_cli.commands._options import claim_outputs

    with atomic_dir(tmp_path / "seg") as tmp:
        write_json(tmp / "segments.json", {"segments": []})
    part = tmp_path / "seg" / "segments.json"
    with pytest.raises(ForeignOutputError, match="file of the kinfu output folder"):
        claim_output(part, parameter="plot")
    assert claim_output(part, force=True) == part
    assert claim_output(tmp_path / "seg" / "new.png") == tmp_path / "seg" / "new.png"  # a new file beside them
    single = write_json(tmp_path / "views.json", {"x": 1})  # a single-file output is still replaced
    assert claim_output(single) == single
    with pytest.raises(KinfuError, match="inside the output folder") as err:
        claim_outputs({"outdir": tmp_path / "new", "viz": tmp_path / "new" / "segments.json"}, [], False)
    assert err.value.parameter == "outdir/viz"
    claim_outputs({"outdir": tmp_path / "new", "viz": tmp_path / "new.mcap"}, [], False)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc, where nothing can be made")
def test_an_output_nothing_can_be_made_for_is_refused_before_the_work():
    # root passes os.access on /proc; the run failed only after its work (eval fusion printed its warnings first)
    for path in ("/proc/x/y/a.json", "/proc/a.json"):
        with pytest.raises(KinfuError, match="cannot write into the folder /proc"):
            claim_output(path)


def test_the_writability_probe_leaves_nothing_behind(tmp_path):
    claim_output(tmp_path / "a" / "b" / "c.json")
    claim_output(tmp_path / "d.json")
    assert list(tmp_path.iterdir()) == []


def test_a_folder_of_many_files_is_claimed_on_a_few_manifest_reads(tmp_path, monkeypatch):
    # each file's check read the folder's manifest again: 3,000 segment files took 5.8 s to claim
    import json

    from kinfu_cli.core import ownership

    out = tmp_path / "seg"
    out.mkdir()
    for i in range(500):
        (out / f"segment_{i:03d}.ply").write_bytes(b"ply")
    ownership.record_tree(out)
    ownership.mark_folder_output(out)
    reads = []
    real_loads = json.loads
    monkeypatch.setattr(ownership.json, "loads", lambda text, *a, **k: reads.append(1) or real_loads(text, *a, **k))
    assert claim_output(out) == out and ownership.holds_only_kinfu_entries(out)
    assert len(reads) <= 2  # the folder's manifest, and its parent's (none here)
    # a manifest another process replaced is read again, not taken from memory
    doc = json.loads((out / MANIFEST).read_text())
    del doc["files"]["segment_000.ply"]
    (tmp_path / "new.json").write_text(json.dumps(doc) + " " * 64)  # another size: a new document either way
    os.replace(tmp_path / "new.json", out / MANIFEST)
    assert not written_by_kinfu(out / "segment_000.ply") and written_by_kinfu(out / "segment_001.ply")
    # and one this process rewrites too
    ownership.record_written(out / "segment_000.ply")
    assert written_by_kinfu(out / "segment_000.ply")
