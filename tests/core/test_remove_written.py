"""remove_written: kinfu removes what it wrote and nobody changed since, never a user's file, and a kinfu folder that
holds a user's file loses kinfu's files (no result left looking complete) but stays kinfu's for the next write."""

from __future__ import annotations

from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.ownership import MANIFEST, changed_since_written, remove_written, written_by_kinfu


def _result(folder):
    with atomic_dir(folder) as tmp:
        write_json(tmp / "segments.json", {"segments": []})
        (tmp / "cloud.ply").write_bytes(b"kinfu cloud")
        (tmp / "parts").mkdir()
        (tmp / "parts" / "0.ply").write_bytes(b"kinfu part")
    return folder


def test_a_kinfu_file_or_whole_folder_goes(tmp_path):
    out = write_json(tmp_path / "pois.json", {"pois": []})
    assert remove_written(out) == ([out], []) and not out.exists()
    seg = _result(tmp_path / "segment")
    assert remove_written(seg) == ([seg], []) and not seg.exists()


def test_what_kinfu_did_not_write_is_left_alone(tmp_path):
    mine = tmp_path / "pois.json"
    mine.write_text("mine")
    assert remove_written(mine) == ([], []) and mine.read_text() == "mine"  # never kinfu's: not even named
    edited = write_json(tmp_path / "views.json", {"pois": []})
    edited.write_text('{"pois": [1]}')
    assert remove_written(edited) == ([], [edited]) and edited.exists()  # kinfu's once, changed since: kept, named


def test_a_users_file_in_a_kinfu_folder_stays_and_kinfus_beside_it_go(tmp_path):
    seg = _result(tmp_path / "segment")
    (seg / "notes.txt").write_text("mine")
    (seg / "parts" / "keep.txt").write_text("mine too")
    removed, kept = remove_written(seg)
    assert sorted(p.relative_to(seg).as_posix() for p in removed) == ["cloud.ply", "parts/0.ply", "segments.json"]
    assert sorted(p.relative_to(seg).as_posix() for p in kept) == ["notes.txt", "parts/keep.txt"]
    left = sorted(p.relative_to(seg).as_posix() for p in seg.rglob("*") if not p.name.startswith(MANIFEST))
    assert left == ["notes.txt", "parts", "parts/keep.txt"]
    assert (seg / "notes.txt").read_text() == "mine"
    # still kinfu's folder, its record naming only what is there: the next result there needs no force
    assert written_by_kinfu(seg) and changed_since_written(seg) == []
    _result(seg)
    assert (seg / "segments.json").is_file() and (seg / "notes.txt").read_text() == "mine"
    assert (seg / "parts" / "keep.txt").read_text() == "mine too"
