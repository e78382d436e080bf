"""Replacing kinfu's output folder never moves the user's entries (a run stopped half-way could delete them),
a user's folder is not kinfu's for holding a kinfu file, and a running kinfu's temporaries are not debris."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from kinfu_cli.core import atomic
from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.errors import KinfuError
from kinfu_cli.core.ownership import MANIFEST, claim_output, written_by_kinfu


def _result(final: Path, value: int, sub: bool = True) -> None:
    with atomic_dir(final) as tmp:
        (tmp / "report.json").write_text(f'{{"run": {value}}}')
        (tmp / "mesh.ply").write_text(f"mesh {value}")
        if sub:
            (tmp / "regions").mkdir()
            (tmp / "regions" / "0.ply").write_text(f"region {value}")


def _user_files(final: Path) -> dict[str, str]:
    return {str(p.relative_to(final)): p.read_text() for p in sorted(final.rglob("*.txt"))}


def test_a_swap_stopped_half_way_keeps_every_user_file(tmp_path, monkeypatch):
    final = tmp_path / "out"
    _result(final, 1)
    for i in range(20):
        (final / f"note{i}.txt").write_text(str(i))
    (final / "regions" / "mine.txt").write_text("inside kinfu's subfolder")
    before = _user_files(final)
    real_replace, calls = os.replace, []

    def failing(src, dst):
        if final in Path(src).parents or final in Path(dst).parents:
            calls.append(src)
            if len(calls) == 3:  # the third rename into or out of the output fails (a full disk, Ctrl-C)
                raise KeyboardInterrupt
        return real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", failing)
    with pytest.raises(KeyboardInterrupt):
        _result(final, 2)
    monkeypatch.undo()
    assert _user_files(final) == before  # the old swap had moved them into the new folder and deleted them
    assert not (final / "report.json").exists() or (final / "report.json").read_text() == '{"run": 1}'
    _result(final, 3)  # the next run takes the folder back
    assert _user_files(final) == before and (final / "report.json").read_text() == '{"run": 3}'
    assert sorted(p.name for p in tmp_path.iterdir() if ".part" in p.name) == []  # no temporaries left


def test_a_rerun_replaces_kinfu_entries_and_keeps_the_users_in_place(tmp_path):
    final = tmp_path / "out"
    _result(final, 1)
    (final / "notes.txt").write_text("mine")
    (final / "regions" / "mine.txt").write_text("mine too")
    _result(final, 2, sub=False)  # the new result has no regions/: kinfu's entries there go, the user's stay
    assert (final / "mesh.ply").read_text() == "mesh 2" and (final / "notes.txt").read_text() == "mine"
    assert (final / "regions" / "mine.txt").read_text() == "mine too"
    assert not (final / "regions" / "0.ply").exists()
    with pytest.raises(KinfuError, match="regions there was not written by kinfu"):
        _result(final, 3)  # regions/ is the user's folder now: a new regions/ would replace it
    assert (final / "regions" / "mine.txt").read_text() == "mine too"
    assert (final / "mesh.ply").read_text() == "mesh 2"  # the swap stopped before anything moved


def test_a_users_folder_at_a_kinfu_subfolders_name_is_not_replaced_without_force(tmp_path):
    final = tmp_path / "out"
    _result(final, 1)
    shutil.rmtree(final / "regions")
    (final / "regions").mkdir()
    (final / "regions" / "my_annotation.txt").write_text("mine")
    with pytest.raises(KinfuError, match="regions there was not written by kinfu"):
        with atomic_dir(final) as tmp:
            (tmp / "regions").mkdir()
            (tmp / "regions" / "0.ply").write_text("new")
    assert (final / "regions" / "my_annotation.txt").read_text() == "mine"


def test_a_users_folder_holding_a_kinfu_file_is_not_kinfus(tmp_path):
    ud = tmp_path / "ud"
    ud.mkdir()
    (ud / "thesis.txt").write_text("mine")
    write_json(ud / "pois.json", {"pois": []})  # kinfu poi -o ud/pois.json
    assert not written_by_kinfu(ud)
    with pytest.raises(KinfuError, match="kinfu did not write"):
        claim_output(ud)
    (ud / "thesis.txt").unlink()  # a folder holding only kinfu's files is kinfu's to replace
    assert written_by_kinfu(ud)


def test_an_output_that_is_a_symlink_replaces_the_link_not_the_folder_it_points_to(tmp_path):
    target = tmp_path / "users"
    target.mkdir()
    (target / "keep.txt").write_text("mine")
    link = tmp_path / "link"
    link.symlink_to(target)
    _result(link, 1)
    assert not link.is_symlink() and (link / "report.json").is_file()
    assert sorted(p.name for p in target.iterdir()) == ["keep.txt"]


def test_a_running_kinfus_temporary_folder_is_not_cleared_as_debris(tmp_path):
    final = tmp_path / "out"
    with atomic_dir(final) as first:
        (first / "report.json").write_text("first")
        with atomic_dir(final) as second:  # a second run on the same output starts meanwhile
            (second / "report.json").write_text("second")
        assert (first / "report.json").read_text() == "first"  # before, the second run deleted it as debris
    assert (final / "report.json").read_text() == "first"


@pytest.mark.parametrize("make, needle", [
    (lambda d: (d / "plain").write_text("x") and d / "plain" / "v.mcap", "plain is a file, not a folder"),
    (lambda d: d / ("p" * 240 + ".json"), "a name of 245 bytes; expected at most 231"),
    (lambda d: d / ".kinfu-manifest.json", "kinfu's own record"),
    (lambda d: d / "kf" / "sub" / "..", "expected a path ending in a file or folder name"),
])
def test_outputs_kinfu_cannot_write_are_refused_before_the_work(tmp_path, make, needle):
    with pytest.raises(KinfuError, match=needle):
        claim_output(make(tmp_path), parameter="--viz")


def test_a_copy_of_a_kinfu_folder_is_refused_before_the_work_not_at_the_swap(tmp_path):
    final = tmp_path / "out"
    _result(final, 1)
    copy = tmp_path / "copy"
    shutil.copytree(final, copy, copy_function=shutil.copy)  # as cp -r: new modification times
    os.utime(copy / "mesh.ply", ns=(1, 1))
    with pytest.raises(KinfuError, match=r"copy/mesh.ply, copy/regions/0.ply, copy/report.json there changed since kinfu wrote them"):
        claim_output(copy)
    claim_output(copy, force=True)
    claim_output(final)  # kinfu's own, unchanged


@pytest.mark.parametrize("stop_at", [1, 2, 3, 4])
def test_a_swap_stopped_early_leaves_no_old_result_json_beside_missing_files(tmp_path, monkeypatch, stop_at):
    """kinfu's old entries go out JSON first (alphabetical order left report.json beside a deleted mesh.ply)."""
    final = tmp_path / "out"
    _result(final, 1, sub=False)
    (final / "notes.txt").write_text("mine")  # a user's file: the swap is done in place
    real_replace, calls = os.replace, []

    def failing(src, dst):
        if final in Path(src).parents or final in Path(dst).parents:
            calls.append(src)
            if len(calls) == stop_at:
                raise KeyboardInterrupt
        return real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", failing)
    with pytest.raises(KeyboardInterrupt):
        _result(final, 2, sub=False)
    monkeypatch.undo()
    report = final / "report.json"
    assert not report.exists() or (final / "mesh.ply").read_text() == report.read_text().replace(
        '{"run": ', "mesh ").rstrip("}")
    assert (final / "notes.txt").read_text() == "mine"


def test_an_all_kinfu_folder_is_swapped_whole(tmp_path, monkeypatch):
    final = tmp_path / "out"
    _result(final, 1)
    moved = []
    real_replace = os.replace
    monkeypatch.setattr(atomic.os, "replace", lambda s, d: (moved.append((Path(s), Path(d))), real_replace(s, d)))
    _result(final, 2)
    monkeypatch.undo()
    into_final = [d for _, d in moved if d == final or final in d.parents and MANIFEST not in d.name]
    assert into_final == [final]  # one rename of the whole new folder, no entry by entry
    assert (final / "regions" / "0.ply").read_text() == "region 2"


def test_a_users_symlink_at_a_kinfu_subfolders_name_is_not_replaced_without_force(tmp_path):
    final = tmp_path / "out"
    _result(final, 1)
    shutil.rmtree(final / "regions")
    users = tmp_path / "users"
    users.mkdir()
    (users / "keep.txt").write_text("mine")
    (final / "regions").symlink_to(users)
    with pytest.raises(KinfuError, match="regions there was not written by kinfu"):
        _result(final, 2)
    assert (final / "regions").is_symlink() and (users / "keep.txt").read_text() == "mine"


def test_no_manifest_temporary_is_left_by_ctrl_c_and_a_killed_runs_is_cleared(tmp_path, monkeypatch):
    import json as json_module

    from kinfu_cli.core import ownership

    folder = tmp_path / "f"
    folder.mkdir()
    stale = folder / f"{MANIFEST}.abcd1234.part"
    stale.write_text("{")
    os.utime(stale, (1, 1))  # a killed run's, long ago
    monkeypatch.setattr(ownership.json, "dump", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt))
    with pytest.raises(KeyboardInterrupt):
        write_json(folder / "a.json", {})
    monkeypatch.setattr(ownership.json, "dump", json_module.dump)
    assert sorted(p.name for p in folder.iterdir()) == ["a.json"]


def test_a_killed_mcap_writers_scratch_folder_is_cleared_by_the_next_run(tmp_path):
    """rosbags writes an .mcap inside a bag folder: a killed import left `.NAME.xxxxxxxx.part/` for good."""
    from kinfu_cli.io.writers import RecordingWriter

    debris = tmp_path / ".rec.abcd1234.part"
    (debris / "rec").mkdir(parents=True)
    (debris / "rec" / "rec.mcap").write_bytes(b"partial")
    with RecordingWriter(tmp_path / "rec.mcap") as w:
        w.write_tf(1, [("world", "camera", np.eye(4))])
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != MANIFEST) == ["rec.mcap"]


def test_only_kinfus_exact_temporary_names_are_taken_for_its_own(tmp_path):
    """A folder removed whole (batch's earlier outputs of a failed stage) must hold only kinfu's entries: a user's
    `.notes.part.txt` or `.kinfu-manifest.json.bak` was skipped by the check as kinfu's debris, then removed."""
    from kinfu_cli.core.ownership import holds_only_kinfu_entries

    final = tmp_path / "out"
    _result(final, 1)
    assert holds_only_kinfu_entries(final)
    (final / ".out.abcd1234.part").mkdir()  # a killed run's temporary: kinfu's
    assert holds_only_kinfu_entries(final)
    for name in (".notes.part.txt", f"{MANIFEST}.bak"):
        (final / "regions" / name).write_text("mine")
        assert not holds_only_kinfu_entries(final)
        (final / "regions" / name).unlink()
