"""A stage output a user changed is no longer kinfu's: `kinfu batch` neither counts the stage current nor
uses or replaces the file, and names it.

Before: after a batch run of fuse + eval-fusion on the sample, moving the vertices of fuse/mesh.ply 5 cm up
left fuse `skipped` (volume.npz and report.json unchanged) and re-ran eval-fusion on the edited mesh (`ok`, no
word); only --redo stopped, at the folder swap ("mesh.ply there was not written by kinfu and would be replaced"),
and --force stopped there too, though it is to write over outputs kinfu did not write.
"""

from __future__ import annotations

import os

from kinfu_cli.batch.engine import run_task
from kinfu_cli.batch.plan import PlanRecording
from kinfu_cli.batch.stages import RECORDING, StageRun, StageSpec
from kinfu_cli.core.atomic import atomic_dir, write_json


def _fuse_like(rec, options, force):
    """A stage writing a folder as `kinfu fuse` does: volume + report (its outputs), mesh + cloud beside them."""
    with atomic_dir(rec.output / "fuse", own=("*",), force=force) as tmp:
        for name in ("volume.npz", "mesh.ply", "cloud.ply"):
            (tmp / name).write_bytes(b"kinfu " + name.encode())
        write_json(tmp / "report.json", {"frames": {"used": 3}})
    return StageRun({"frames": 3})


SPEC = StageSpec("fuse", (), (RECORDING,), ("fuse/volume.npz", "fuse/report.json"), ("fuse",), lambda r, o: None,
                 _fuse_like)
POIS = StageSpec("poi", (), (RECORDING,), ("pois.json",), ("pois.json",), lambda r, o: None,
                 lambda rec, options, force: (write_json(rec.output / "pois.json", {"pois": []}), StageRun())[1])


def _rec(tmp_path) -> PlanRecording:
    recording = tmp_path / "rec.mcap"
    recording.write_bytes(b"recording")
    return PlanRecording(recording, tmp_path / "out", {}, "rec.mcap", ("fuse", "poi"))


def test_an_edited_mesh_makes_the_stage_not_current_and_is_kept(tmp_path):
    rec = _rec(tmp_path)
    first = run_task(SPEC, rec, {}, None, False)
    assert first["status"] == "ok"
    assert run_task(SPEC, rec, {}, first, False)["status"] == "skipped"  # untouched: current
    mesh = rec.output / "fuse" / "mesh.ply"
    mesh.write_bytes(b"the user's mesh")
    again = run_task(SPEC, rec, {}, first, False)
    assert again["status"] == "failed" and "fuse/mesh.ply" in again["error"], again
    assert "changed since kinfu wrote it" in again["error"]
    assert mesh.read_bytes() == b"the user's mesh"
    redo = run_task(SPEC, rec, {}, None, False)  # --redo: no previous entry, still not replaced
    assert redo["status"] == "failed" and mesh.read_bytes() == b"the user's mesh"
    os.rename(mesh, tmp_path / "kept.ply")  # moved away: the stage runs again
    assert run_task(SPEC, rec, {}, None, False)["status"] == "ok"


def test_an_edited_single_file_output_is_named(tmp_path):
    rec = _rec(tmp_path)
    first = run_task(POIS, rec, {}, None, False)
    (rec.output / "pois.json").write_text('{"pois": [{"id": 0}]}')
    again = run_task(POIS, rec, {}, first, False)
    assert again["status"] == "failed" and again["error"].startswith("pois.json in "), again


def test_force_replaces_the_edited_file_and_keeps_the_users_others(tmp_path):
    rec = _rec(tmp_path)
    run_task(SPEC, rec, {}, None, False)
    (rec.output / "fuse" / "mesh.ply").write_bytes(b"the user's mesh")
    (rec.output / "fuse" / "notes.txt").write_text("mine")
    assert run_task(SPEC, rec, {}, None, True)["status"] == "ok"
    assert (rec.output / "fuse" / "mesh.ply").read_bytes() == b"kinfu mesh.ply"
    assert (rec.output / "fuse" / "notes.txt").read_text() == "mine"
