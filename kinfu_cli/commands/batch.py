"""`kinfu batch`: the stages of a plan over many recordings on Dask, resumable, with manifest.json."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinfu_cli.batch.engine import check_before_work, connect, run_plan
from kinfu_cli.batch.lock import batch_lock
from kinfu_cli.batch.manifest import MANIFEST_NAME
from kinfu_cli.batch.plan import load_plan
from kinfu_cli.commands._batch_stages import VIEWER_FILES, batch_stages
from kinfu_cli.commands._options import OutputPath
from kinfu_cli.commands._output_path import output_kind_problem
from kinfu_cli.core.errors import ConfigError


@click.command("batch", short_help="Run the stages of a plan over many recordings on Dask (resumable).")
@click.argument("plan", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=OutputPath(file_okay=False, kind="folder"), default=None,
              help="Output folder: one sub-folder per recording and manifest.json [the plan's 'output'].")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes of the local cluster, one thread each [one per core].")
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
              help="Submit to this running dask.distributed scheduler instead of a local cluster (its workers "
                   "must see the same paths).")
@click.option("--viz", default=None, metavar="FILE.mcap",
              help="Also write one viewer file of this name into each recording's folder: its stages' results "
                   "(mesh, camera and hand trajectories, POIs, ranked views, segments) in one MCAP for Foxglove "
                   "[the plan's 'viz'].")
@click.option("--force", is_flag=True,
              help="Redo every stage even when its outputs are current, and write over outputs kinfu did not "
                   "write (an input is never written over).")
@click.option("--redo", is_flag=True,
              help="Redo every stage even when its outputs are current (kinfu's own outputs are replaced; unlike "
                   "--force, outputs kinfu did not write are still refused).")
@click.option("--json", "as_json", is_flag=True, help="Print manifest.json on stdout.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def command(plan: Path, output: Path | None, workers: int | None, scheduler: str | None, viz: str | None,
            force: bool, redo: bool, as_json: bool, quiet: bool) -> None:
    """Run the stages listed in PLAN (TOML or YAML) over every recording it names: one Dask task per
    (recording, stage), the stage dependencies as the graph (poi needs the recording, segment needs fuse,
    nbv needs fuse and poi, diff needs fuse and its `before`, eval-fusion needs fuse, eval-poi needs poi,
    eval-segment needs segment; eval-nbv needs only the ground truth).
    Each stage is the single command run in-process on a worker with the plan's options, writing what the
    command writes into OUTPUT/<recording>/: fuse/, pois.json, views.json, segment/, diff/ (`kinfu diff`
    against the recording's `before`: another recording of the plan or a volume.npz; with --pois when the
    recording has poi), eval_fusion.json (`kinfu eval fusion` against its ground truth) and eval_poi.json
    (its POIs against the true changes, 0.20 m rule), eval_nbv.json (`kinfu eval nbv`: the simulated NBV
    loop on its ground-truth scene) and eval_segment.json (`kinfu eval segment` of segment/ against the
    ground truth's labels.npz, else labels.ply). Evaluations find the ground truth in the ground_truth/
    folder beside the recording (kinfu synth's layout) or the entry's `ground-truth`.
    --viz FILE.mcap writes OUTPUT/<recording>/FILE.mcap, one viewer file combining the viewer files its
    stages write (fuse.mcap, pois.mcap, views.mcap, segment.mcap). OUTPUT/manifest.json records per
    recording and stage the status (ok, skipped, failed, blocked), seconds, key numbers, warnings and the
    error line, and is rewritten after every task. One run at a time per OUTPUT: a second `kinfu batch` on
    the same folder stops at once with one line naming OUTPUT/.kinfu-batch.lock.

    Resumable: a stage whose outputs exist unchanged with the same input fingerprint (inputs' size and
    modification time, options, kinfu version) is skipped; --redo redoes everything (--force too, and it also
    writes over outputs kinfu did not write). A failing recording
    does not stop the others; the exit code is 1 when one failed, 2 for a bad plan (checked before any work:
    unknown stages or options, options for a stage no recording runs, option values the stage's command refuses,
    missing files, globs matching nothing, a diff without `before`, an evaluation without ground truth, two
    recordings with one output folder, an existing OUTPUT or recording folder holding files kinfu did not
    write (unless --force, which writes beside them and replaces only a file named as an output), an
    unreachable --scheduler).

    \b
    Example plan (examples/batch_plan.toml):
      output = "out/batch"
      stages = ["fuse", "poi", "nbv", "segment"]
      recordings = ["sessions/*.mcap", {path = "lab/day2.bag", output = "day2"},
                    {path = "lab/day3.bag", stages = ["fuse", "poi", "diff"], before = "lab/day2.bag"}]
      [options.fuse]
      voxel-size = 0.02
    \b
    Example:
      kinfu batch examples/batch_plan.toml
      kinfu batch plan.yaml -o out/batch --workers 4
      kinfu batch plan.toml --scheduler tcp://10.0.0.5:8786
      kinfu batch plan.toml --viz viewer.mcap
    """
    if scheduler is not None and workers is not None:
        raise ConfigError("--workers: sizes the local cluster; with --scheduler the cluster has its own workers")
    table = batch_stages()
    loaded = load_plan(plan, table, output, viz)
    problem = output_kind_problem(loaded.output, "folder")  # -o runs.json (the plan checks viz's name)
    if problem is not None:
        raise loaded.output_error(ConfigError(problem))
    if loaded.viz in VIEWER_FILES.values():  # the combined file would replace a stage's part and merge into itself
        where = "--viz" if viz is not None else f"{plan}: viz"
        raise ConfigError(f"{where}: {loaded.viz} is the name of a stage's own viewer file ("
                          f"{', '.join(sorted(VIEWER_FILES.values()))}); name the combined file otherwise")
    check_before_work(loaded, table, force)  # before the lock file goes into a user's folder
    with batch_lock(loaded.output, loaded.output_error):  # a second run on this folder fails here, before any work
        engine = connect(scheduler, workers)
        try:
            doc = run_plan(loaded, table, engine, force=force, quiet=quiet, redo=redo)
        finally:
            engine.close()
    if as_json:
        click.echo(json.dumps(doc, indent=2))
    s = doc["summary"]
    where = loaded.output / MANIFEST_NAME
    ran = sum(e["status"] == "ok" for r in doc["recordings"] for e in r["stages"].values())
    skipped = sum(e["status"] == "skipped" for r in doc["recordings"] for e in r["stages"].values())
    if s["failed"]:
        click.echo(f"kinfu: batch: {s['done']} of {s['recordings']} recordings done, {s['failed']} failed "
                   f"(see {where})", err=True)
        click.get_current_context().exit(1)
    click.echo(f"kinfu: batch: {s['done']} of {s['recordings']} recordings done ({ran} stages run, {skipped} "
               f"skipped) -> {where}", err=True)
