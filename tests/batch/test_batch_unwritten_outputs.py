"""A redone stage leaves none of its earlier outputs that this run does not write, nor the combined viewer file of a
dropped `viz`, and names what another recording's dropped diff may have read:

- nbv redone with `plot` switched off left the views.png of the earlier views beside the new views.json (and fuse
  and poi redone without `viz`, their fuse.mcap / pois.mcap): now removed, kinfu's unchanged files only, a user's
  edited one kept with a warning;
- a plan dropping `viz` (or renaming its file) left the combined FILE.mcap the earlier plan named: now its name is
  read from the earlier run's manifest.json (`viewer`) and the file removed under the same rules;
- recording b's diff compared against a's fuse; after b dropped diff and a's fuse was redone, b/diff stayed. The
  manifest does not record which recording a diff's `before` named, so it is left, and a's fuse entry names it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from click.testing import CliRunner

from kinfu_cli.batch.engine import stale_stages, with_earlier
from kinfu_cli.batch.manifest import build_manifest, write_manifest
from kinfu_cli.batch.plan import load_plan
from kinfu_cli.cli import cli
from kinfu_cli.commands._batch_stages import batch_stages
from kinfu_cli.sim.synth import synthesize


def _recordings(tmp_path: Path, *names: str) -> None:
    synthesize(tmp_path / "synth", seed=0, width=32, height=24, frames=4, formats=("mcap",))
    for name in names:
        shutil.copy(tmp_path / "synth" / "recording.mcap", tmp_path / name)


def _run(plan: Path, scheduler: str, *more: str) -> dict:
    """{output folder name: its stage entries} after a run that must succeed."""
    run = CliRunner().invoke(cli, ["batch", str(plan), "--scheduler", scheduler, "--quiet", *more],
                             catch_exceptions=False)
    assert run.exit_code == 0, run.output
    doc = json.loads((plan.parent / "out" / "manifest.json").read_text())
    return {Path(r["output"]).name: r["stages"] for r in doc["recordings"]}


def _said(stages: dict, start: str) -> list[str]:
    """The warnings of every stage of a recording that begin with `start`."""
    return [w for e in stages.values() for w in e["warnings"] if w.startswith(start)]


def _edit(path: Path) -> None:
    """A user's change to a file kinfu wrote: it is the user's now (a batch run over its folder then needs
    --force, which redoes every stage)."""
    path.write_bytes(path.read_bytes() + b"\0")


NBV = """output = "out"
stages = ["fuse", "poi", "nbv"]
recordings = ["a.mcap", "b.mcap"]
[options.fuse]
voxel-size = 0.04
[options.nbv]
plot = {plot}
"""


def test_a_plot_switched_off_goes_when_its_stage_is_redone(tmp_path, scheduler):
    _recordings(tmp_path, "a.mcap", "b.mcap")
    plan = tmp_path / "plan.toml"
    plan.write_text(NBV.format(plot="true"))
    _run(plan, scheduler)
    a, b = tmp_path / "out" / "a", tmp_path / "out" / "b"
    assert (a / "views.png").is_file() and (b / "views.png").is_file()

    plan.write_text(NBV.format(plot="false"))  # nbv redone without its plot
    stages = _run(plan, scheduler)
    for rec in (a, b):  # before: the plot of the earlier views stayed beside the new views.json
        assert (rec / "views.json").is_file() and not (rec / "views.png").exists()
        st = stages[rec.name]
        assert st["nbv"]["status"] == "ok" and st["fuse"]["status"] == st["poi"]["status"] == "skipped"
        (said,) = st["nbv"]["warnings"]
        assert said.startswith("the nbv outputs of an earlier run: removed views.png: this run of nbv does not "
                               "write them"), said

    plan.write_text(NBV.format(plot="true"))
    _run(plan, scheduler)
    _edit(b / "views.png")
    plan.write_text(NBV.format(plot="false"))
    stages = _run(plan, scheduler, "--force")  # every stage redone: the fuse first removes nbv's outputs
    assert not (a / "views.png").exists()
    (said,) = _said(stages["a"], "the nbv outputs of an earlier run")  # by fuse or poi, whichever ran first
    assert said.startswith("the nbv outputs of an earlier run: removed views.png: this run of nbv"), said
    assert (b / "views.png").is_file()  # the user's now: kept, and said once, by nbv
    (said,) = _said(stages["b"], "the nbv outputs of an earlier run")
    assert said in stages["b"]["nbv"]["warnings"], stages["b"]
    assert said.startswith("the nbv outputs of an earlier run: kept views.png (not written by kinfu, or changed"), said


VIZ = """output = "out"
stages = ["fuse", "poi"]
recordings = ["a.mcap", "b.mcap"]
{viz}
[options.fuse]
voxel-size = 0.04
"""


def test_viewer_files_of_a_dropped_or_renamed_viz_go(tmp_path, scheduler):
    _recordings(tmp_path, "a.mcap", "b.mcap")
    plan = tmp_path / "plan.toml"
    plan.write_text(VIZ.format(viz='viz = "scene.mcap"'))
    _run(plan, scheduler)
    a, b = tmp_path / "out" / "a", tmp_path / "out" / "b"
    for rec in (a, b):
        assert all((rec / n).is_file() for n in ("fuse.mcap", "pois.mcap", "scene.mcap"))

    plan.write_text(VIZ.format(viz='viz = "other.mcap"'))  # renamed: only the combined file is redone
    stages = _run(plan, scheduler)
    assert stages["a"]["fuse"]["status"] == "skipped" and stages["a"]["viz"]["status"] == "ok"
    for rec in (a, b):
        assert (rec / "other.mcap").is_file() and not (rec / "scene.mcap").exists()
    (said,) = stages["a"]["viz"]["warnings"]
    assert said.startswith("the viz outputs of an earlier run: removed scene.mcap: this run of viz does not"), said
    _edit(b / "other.mcap")
    _edit(b / "fuse.mcap")

    plan.write_text(VIZ.format(viz=""))  # viz dropped: fuse and poi redone without their viewer files
    # a run of it stopped before any stage ran (Ctrl-C, killed) rewrote the manifest without a viewer: it still
    # names the earlier plan's file, so the next run knows it
    manifest = tmp_path / "out" / "manifest.json"
    table = batch_stages()
    write_manifest(manifest, build_manifest(with_earlier(load_plan(plan, table), table, manifest), {}, "stopped"))
    recs = json.loads(manifest.read_text())["recordings"]
    assert [(r.get("viewer"), r["earlier_viewers"]) for r in recs] == [(None, [str(a / "other.mcap")]),
                                                                       (None, [str(b / "other.mcap")])]
    stages = _run(plan, scheduler, "--force")
    assert all(e["status"] == "ok" for rec in ("a", "b") for e in stages[rec].values())
    assert "viz" not in stages["a"]
    for name in ("fuse.mcap", "pois.mcap", "other.mcap"):  # before: all three stayed beside the new results
        assert not (a / name).exists(), name
    assert _said(stages["a"], "the fuse outputs of an earlier run: removed fuse.mcap: this run of fuse does not")
    assert _said(stages["a"], "the poi outputs of an earlier run: removed pois.mcap: this run of poi does not")
    (said,) = _said(stages["a"], "the viz outputs of an earlier run:")  # by fuse or poi, whichever came first
    assert "removed other.mcap: viz is not in this plan" in said, said
    # b's edited files are the user's: kept and named, kinfu's beside them go
    assert (b / "other.mcap").is_file() and (b / "fuse.mcap").is_file() and not (b / "pois.mcap").exists()
    assert _said(stages["b"], "the fuse outputs of an earlier run: kept fuse.mcap (not written by kinfu")
    assert all("kept other.mcap (not written by kinfu" in w for w in _said(stages["b"], "the viz outputs"))
    assert _said(stages["b"], "the viz outputs")
    # a's is gone: no longer named; b's, kept, is, so it goes once it is kinfu's again (and said each time)
    recs = json.loads(manifest.read_text())["recordings"]
    assert "earlier_viewers" not in recs[0] and recs[1]["earlier_viewers"] == [str(b / "other.mcap")]


DIFF = """output = "out"
stages = ["fuse"]
recordings = [{{path = "a.mcap", output = "a", options = {{fuse = {{voxel-size = {voxel}}}}}}},
              {{path = "b.mcap", output = "b", stages = {b_stages}{before}}}]
[options.fuse]
voxel-size = 0.04
"""


def test_another_recordings_dropped_diff_is_named_when_its_before_is_redone(tmp_path, scheduler):
    _recordings(tmp_path, "a.mcap", "b.mcap")
    plan = tmp_path / "plan.toml"
    plan.write_text(DIFF.format(voxel=0.04, b_stages='["fuse", "diff"]', before=', before = "a"'))
    stages = _run(plan, scheduler)
    b_diff = tmp_path / "out" / "b" / "diff"
    assert stages["b"]["diff"]["status"] == "ok" and (b_diff / "changes.json").is_file()

    plan.write_text(DIFF.format(voxel=0.05, b_stages='["fuse"]', before=""))  # a's fuse redone, b's diff dropped
    stages = _run(plan, scheduler)
    assert stages["a"]["fuse"]["status"] == "ok" and stages["b"]["fuse"]["status"] == "skipped"
    assert (b_diff / "changes.json").is_file()  # which volume it read is not recorded: left, and named
    (said,) = _said(stages["a"], "the diff outputs")  # by a's fuse
    assert said.startswith(f"the diff outputs of an earlier run: left {b_diff}: this plan no longer runs diff"), said
    assert said in stages["a"]["fuse"]["warnings"] and said.endswith("if they were, they match nothing: remove them")
    assert not _said(stages["b"], "the diff outputs")

    again = _run(plan, scheduler)  # a's fuse not redone: not said again
    assert again["a"]["fuse"]["status"] == "skipped" and not _said(again["a"], "the diff outputs")


def test_the_earlier_viewer_file_is_read_from_kinfus_manifest_in_the_recordings_folder_only(tmp_path):
    for name in ("a.mcap", "b.mcap", "c.mcap"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "plan.toml").write_text(VIZ.format(viz="").replace('"b.mcap"', '"b.mcap", "c.mcap"'))
    table = batch_stages()
    plan = load_plan(tmp_path / "plan.toml", table)
    out = tmp_path / "out"
    out.mkdir()
    manifest = out / "manifest.json"
    write_manifest(manifest, {"recordings": [  # as kinfu wrote it: one good name, and two it would never write
        {"output": str(out / "a"), "viewer": str(out / "a" / "scene.mcap")},
        {"output": str(out / "b"), "viewer": str(out / "b" / "pois.json")},
        {"output": str(out / "c"), "viewer": str(out / "elsewhere" / "scene.mcap")}]})
    a, b, c = with_earlier(plan, table, manifest).recordings
    assert a.earlier == {"viz": (out / "a" / "scene.mcap",)} and b.earlier == {} and c.earlier == {}
    assert [s.name for s in stale_stages(table, a, "fuse")][-1] == "viz"  # its combined file goes with the fuse
    assert "viz" not in [s.name for s in stale_stages(table, b, "fuse")]

    manifest.write_text(manifest.read_text().replace("pois.json", "other.mcap"))  # a user's edit: not trusted
    assert [r.earlier for r in with_earlier(plan, table, manifest).recordings] == [{}, {}, {}]
