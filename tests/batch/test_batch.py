"""`kinfu batch` end to end on a 2-worker Dask cluster: three tiny recordings (one truncated), resume after an
interrupted run, --force, the same manifest from the local default and from a scheduler address, and bad
input refused with one line before any work."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import one_line_error

from kinfu_cli.cli import cli
from kinfu_cli.core.atomic import write_json
from kinfu_cli.core.ownership import written_by_kinfu
from kinfu_cli.sim.synth import synthesize

FRAMES = 4
PLAN = """output = "out"
stages = ["fuse", "poi", "nbv", "segment"]
recordings = ["recs/*.mcap"]
[options.fuse]
voxel-size = 0.04
[options.nbv]
lon-step = 90
roll-step = 180
lat-step = 30
[options.segment]
no-superquadrics = true
"""
# fields that differ between two equal runs: timings, stat-based fingerprints, where it ran
_VOLATILE = {"seconds", "fingerprint", "outputs"}


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> Path:
    """recs/a.mcap and recs/b.mcap (tiny synthetic tabletops), recs/broken.mcap (a truncated copy)."""
    base = tmp_path_factory.mktemp("batch_recs")
    (base / "recs").mkdir()
    for name, seed in (("a", 0), ("b", 1)):
        synthesize(base / f"synth_{name}", seed=seed, width=32, height=24, frames=FRAMES, formats=("mcap",))
        shutil.copy(base / f"synth_{name}" / "recording.mcap", base / "recs" / f"{name}.mcap")
    data = (base / "recs" / "a.mcap").read_bytes()
    (base / "recs" / "broken.mcap").write_bytes(data[: len(data) // 3])
    return base


def _workspace(recordings: Path, tmp: Path, plan: str = PLAN) -> Path:
    """A plan folder whose recs/ links to the shared recordings; returns the plan path."""
    (tmp / "recs").symlink_to(recordings / "recs", target_is_directory=True)
    (tmp / "plan.toml").write_text(plan)
    return tmp / "plan.toml"


def _batch(*args):
    return CliRunner().invoke(cli, ["batch", *map(str, args), "--quiet"], catch_exceptions=False)


def _manifest(plan: Path) -> dict:
    return json.loads((plan.parent / "out" / "manifest.json").read_text())


def _statuses(doc: dict) -> dict[str, dict[str, str]]:
    return {Path(r["recording"]).name: {s: e["status"] for s, e in r["stages"].items()} for r in doc["recordings"]}


def _comparable(doc: dict, root: Path) -> dict:
    """The manifest without timings, fingerprints, output stats, engine, and with paths relative to root."""
    doc = json.loads(json.dumps(doc).replace(str(root), "ROOT"))
    recs = [{**r, "stages": {s: {k: v for k, v in e.items() if k not in _VOLATILE} for s, e in r["stages"].items()}}
            for r in doc["recordings"]]
    return {**{k: v for k, v in doc.items() if k not in ("engine", "plan", "output")}, "recordings": recs}


@pytest.fixture(scope="module")
def first_run(recordings, scheduler, tmp_path_factory):
    plan = _workspace(recordings, tmp_path_factory.mktemp("run1"))
    res = _batch(plan, "--scheduler", scheduler)
    return plan, res


@pytest.mark.slow
def test_three_recordings_one_broken(first_run):
    plan, res = first_run
    assert res.exit_code == 1, res.output
    out = plan.parent / "out"
    assert res.output.strip().splitlines()[-1] == (f"kinfu: batch: 2 of 3 recordings done, 1 failed "
                                                   f"(see {out / 'manifest.json'})")
    doc = _manifest(plan)
    assert doc["summary"] == {"recordings": 3, "done": 2, "failed": 1, "pending": 0}
    assert _statuses(doc) == {"a.mcap": dict.fromkeys(("fuse", "poi", "nbv", "segment"), "ok"),
                              "b.mcap": dict.fromkeys(("fuse", "poi", "nbv", "segment"), "ok"),
                              "broken.mcap": {"fuse": "failed", "poi": "failed", "nbv": "blocked",
                                              "segment": "blocked"}}
    broken = doc["recordings"][2]
    assert broken["status"] == "failed" and "broken.mcap" in broken["error"] and "truncated" in broken["error"]
    assert "\n" not in broken["error"]
    for rec in doc["recordings"][:2]:
        st = rec["stages"]
        # key numbers are the outputs' own: every frame fused, POIs found and ranked, the table found
        assert st["fuse"]["numbers"]["frames_used"] == FRAMES and st["fuse"]["numbers"]["occupied"] > 0
        assert st["poi"]["numbers"]["pois"] >= 1 and st["nbv"]["numbers"]["pois"] == st["poi"]["numbers"]["pois"]
        assert st["segment"]["numbers"]["support_plane"] is True
        folder = Path(rec["output"])
        report = json.loads((folder / "fuse" / "report.json").read_text())
        assert report["grid"]["voxel_size"] == 0.04  # the plan's option reached the command
        views = json.loads((folder / "views.json").read_text())
        assert all(p["candidates"] == 4 * 4 * 2 for p in views["pois"])  # lon 90, lat 0..90 by 30, roll 180
        for p in ("fuse", "pois.json", "views.json", "segment"):
            assert written_by_kinfu(folder / p), p
    # the output folders follow the plan's layout; a failed recording leaves nothing that looks complete
    assert [Path(r["output"]) for r in doc["recordings"]] == [out / "recs" / n for n in ("a", "b", "broken")]
    assert not (out / "recs" / "broken" / "fuse").exists()


@pytest.mark.slow
def test_resume_skips_what_is_current(first_run, scheduler, recordings, tmp_path):
    plan, first = first_run
    # a copy of the finished run, so the tests do not depend on each other's order
    work = tmp_path / "w"
    shutil.copytree(plan.parent, work, symlinks=True)
    plan = work / "plan.toml"
    doc = _manifest(plan)
    doc["recordings"] = [{**r, "output": r["output"].replace(str(first_run[0].parent), str(work))}
                         for r in doc["recordings"]]
    # an interrupted run: the manifest knows fuse and poi of a.mcap only, b's segment output is gone
    doc["recordings"][0]["stages"] = {s: e for s, e in doc["recordings"][0]["stages"].items() if s in ("fuse", "poi")}
    write_json(work / "out" / "manifest.json", doc)  # as the client writes it after each task
    shutil.rmtree(work / "out" / "recs" / "b" / "segment")
    res = _batch(plan, "--scheduler", scheduler)
    assert res.exit_code == 1
    got = _statuses(_manifest(plan))
    assert got["a.mcap"] == {"fuse": "skipped", "poi": "skipped", "nbv": "ok", "segment": "ok"}
    assert got["b.mcap"] == {"fuse": "skipped", "poi": "skipped", "nbv": "skipped", "segment": "ok"}
    assert got["broken.mcap"]["fuse"] == "failed"  # a failure is retried, never skipped
    # changed options redo that stage and what depends on it only
    plan.write_text(PLAN.replace("lat-step = 30", "lat-step = 45"))
    _batch(plan, "--scheduler", scheduler)
    got = _statuses(_manifest(plan))
    assert got["a.mcap"] == {"fuse": "skipped", "poi": "skipped", "nbv": "ok", "segment": "skipped"}
    assert json.loads((work / "out" / "recs" / "a" / "views.json").read_text())["pois"][0]["candidates"] == 4 * 3 * 2
    # --force redoes everything
    _batch(plan, "--scheduler", scheduler, "--force")
    got = _statuses(_manifest(plan))
    assert got["b.mcap"] == dict.fromkeys(("fuse", "poi", "nbv", "segment"), "ok")


@pytest.mark.slow
def test_local_default_and_scheduler_give_the_same_manifest(first_run, recordings, tmp_path):
    plan, _ = first_run
    local = _workspace(recordings, tmp_path)
    res = _batch(local, "--workers", "2")
    assert res.exit_code == 1, res.output
    a, b = _manifest(plan), _manifest(local)
    assert a["engine"] != b["engine"] == "local (2 workers)"
    assert _comparable(a, plan.parent) == _comparable(b, local.parent)


def test_bad_input_is_one_line_before_any_work(recordings, tmp_path, quick_refusal):
    plan = _workspace(recordings, tmp_path)
    out = tmp_path / "out"
    for text, needles in ((PLAN.replace('"segment"]', '"segment", "teleport"]'), ["stages", "teleport"]),
                          (PLAN.replace("voxel-size = 0.04", "voxel-siz = 0.04"),
                           ["recordings[0]", "fuse", "unknown option 'voxel-siz'"]),
                          (PLAN.replace("voxel-size = 0.04", 'voxel-size = "fine"'),
                           ["recordings[0]", "fuse", "--voxel-size", "fine"]),
                          (PLAN.replace("lat-step = 30", 'output = "x.json"'), ["nbv", "'output' is set by batch"]),
                          (PLAN.replace('"recs/*.mcap"', '"recs/*.mcap", "recs/missing.bag"'),
                           ["recordings[1]", "missing.bag"]),
                          (PLAN.replace('"recs/*.mcap"', '"recs/a.mcap", {path = "recs/b.mcap", output = "recs/a"}'),
                           ["recordings[1]", "would both write to"])):
        plan.write_text(text)
        one_line_error(_batch(plan), str(plan), *needles)
        assert not out.exists()
    plan.write_text(PLAN)
    one_line_error(_batch(plan, "--scheduler", "tcp://127.0.0.1:9"), "--scheduler", "cannot reach", "127.0.0.1:9")
    one_line_error(_batch(plan, "--scheduler", "localhost"), "--scheduler", "tcp://host")
    one_line_error(_batch(plan, "--scheduler", "tcp://127.0.0.1:9", "--workers", "2"), "--workers", "--scheduler")
    assert not out.exists()
    # a file kinfu did not write where a stage would write is refused (unless --force)
    (out / "recs" / "a").mkdir(parents=True)
    (out / "recs" / "a" / "pois.json").write_text("{}")
    one_line_error(_batch(plan, "--scheduler", "tcp://127.0.0.1:9"), "pois.json", "did not write", "--force")
    assert not (out / "manifest.json").exists()
