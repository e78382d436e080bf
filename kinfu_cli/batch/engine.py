"""Run a plan on Dask: one task per (recording, stage), the stage dependencies as the graph.

The client (this process) submits every task up front; a task receives its upstream tasks' results, so
Dask runs it once they are done, and a task whose upstream failed reports `blocked` without running. The
client writes manifest.json after every finished task. Workers are processes with one thread each, and a
task limits numba to one thread, so N workers use N cores. The same code path serves a local cluster
sized to the machine and an existing `dask.distributed` scheduler (the workers must see the same paths).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import re
import signal
import threading
import time
import uuid
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

from kinfu_cli.batch.fingerprint import input_fingerprint, output_stats
from kinfu_cli.batch.lock import LOCK_NAME
from kinfu_cli.batch.manifest import DONE, MANIFEST_NAME, build_manifest, read_links, read_previous, write_manifest
from kinfu_cli.batch.plan import Plan
from kinfu_cli.batch.stages import StageSpec, stage_dependents
from kinfu_cli.core.errors import ConfigError, KinfuError
from kinfu_cli.core.ownership import (TEMPORARY_NAME, changed_since_written, claim_output, mark_folder_output,
                                      recording_folders, refuse_inside_folders, remove_written, written_by_kinfu)
from kinfu_cli.core.progress import progress

CONNECT_TIMEOUT_S = 5


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


@dataclass
class Engine:
    """A connected Dask client and how to describe it; close() also stops a local cluster it started."""

    client: object
    cluster: object | None
    description: str

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.close()
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close()

    def trial_map(self, desc: str = "trials", quiet: bool = False):
        """A `core.trials.TrialMap` running each trial as one task on this cluster (see map_trials)."""
        return partial(self.map_trials, desc=desc, quiet=quiet)

    def map_trials(self, fn: Callable, items, shared=None, *, desc: str = "trials", quiet: bool = False) -> list:
        """[fn(shared, item) for item in items] as one task per item, in the order of `items`, with a progress
        bar over tasks. `shared` is scattered once (each worker receives it once, not once per trial). A trial
        raising KinfuError raises the same error here, its parameter kept; any other failure cancels the rest."""
        from dask.distributed import as_completed

        items = list(items)
        if not items:
            return []
        run_id = uuid.uuid4().hex[:8]
        shared_f = self.client.scatter(shared, broadcast=True, hash=False) if shared is not None else None
        futures = [self.client.submit(_trial, fn, shared_f, item, key=f"kinfu-trial-{i}-{run_id}", pure=False)
                   for i, item in enumerate(items)]
        try:
            for fut in progress(as_completed(futures, loop=self.client.loop), total=len(futures), desc=desc,
                                quiet=quiet, unit="trial"):
                status, *rest = fut.result()
                if status == "error":
                    cls, detail, parameter = rest
                    raise cls(detail, parameter=parameter)
            return [f.result()[1] for f in futures]
        finally:
            with contextlib.suppress(Exception):
                self.client.cancel(futures + ([shared_f] if shared_f is not None else []))


def connect(scheduler: str | None = None, workers: int | None = None) -> Engine:
    """A client on `scheduler` (tcp://host:port of a running dask.distributed scheduler), or on a new local
    cluster of `workers` single-threaded worker processes (default: one per core). An unreachable scheduler
    is a one-line KinfuError naming it, raised before any work."""
    from dask.distributed import Client

    if scheduler is not None:
        if "://" not in scheduler or not scheduler.split("://", 1)[1]:
            raise ConfigError(f"expected an address like tcp://host:8786, got {scheduler!r}", parameter="scheduler")
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            detail = " ".join(str(exc).split()) or type(exc).__name__
            raise KinfuError(f"cannot reach the Dask scheduler {scheduler} within {CONNECT_TIMEOUT_S} s ({detail})",
                             parameter="scheduler") from None
        return Engine(client, None, scheduler)
    n = default_workers() if workers is None else workers
    if n < 1:
        raise ConfigError(f"expected at least 1, got {n}", parameter="workers")
    # no chatter on stderr: "port 8787 in use" when another cluster runs, and multiprocessing's resource
    # tracker (a process of its own, hence the environment) counting the workers' semaphores after a Ctrl-C
    os.environ.setdefault("PYTHONWARNINGS", "ignore:resource_tracker:UserWarning")
    return _started_deaf_to_sigint(partial(_local_engine, n))


def _local_engine(n: int) -> Engine:
    """A client on a new local cluster of n single-threaded worker processes."""
    from dask.distributed import Client, LocalCluster

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=logging.CRITICAL,
                               env={"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    return Engine(Client(cluster, set_as_default=False), cluster, f"local ({n} workers)")


def _started_deaf_to_sigint(start: Callable[[], Engine]) -> Engine:
    """start() run in a thread that blocks SIGINT, so the worker processes it starts (from threads it starts)
    inherit the blocked signal: a terminal's Ctrl-C reaches the whole process group, and every worker printed
    its KeyboardInterrupt traceback. This thread keeps SIGINT and waits in short joins, so one Ctrl-C at any
    moment of the start-up is a KeyboardInterrupt here at once (before, SIGINT was ignored while the cluster
    started, 1-3 s, and the press was lost); an engine that comes up after that is closed in the background."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        return start()
    with contextlib.suppress(Exception):  # its first start unblocks SIGINT in the starting thread: start it here
        from multiprocessing import resource_tracker

        resource_tracker.ensure_running()
    box: dict = {}
    lock, abandoned = threading.Lock(), threading.Event()

    def run():
        try:
            box["engine"] = start()
        except BaseException as exc:  # handed to the waiting thread
            box["error"] = exc
        with lock:
            box["done"] = True
            if abandoned.is_set() and "engine" in box:
                box["engine"].close()

    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        starter = threading.Thread(target=run, name="kinfu-cluster-start", daemon=True)
        starter.start()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
    try:
        while starter.is_alive():
            starter.join(0.05)
    except BaseException:
        with lock:
            abandoned.set()
            if box.get("done") and "engine" in box:
                threading.Thread(target=box["engine"].close, daemon=True).start()
        raise
    if "error" in box:
        raise box["error"]
    return box["engine"]


def _trial(fn: Callable, shared, item):
    """One trial on a worker: numba on one thread (a worker thread is a core); a KinfuError comes back as data
    (a pickled exception loses its keyword arguments, hence the parameter the command line names)."""
    with contextlib.suppress(Exception):
        import numba

        numba.set_num_threads(1)
    try:
        return ("ok", fn(shared, item))
    except KinfuError as exc:
        return ("error", type(exc), exc.detail, exc.parameter)


def _one_line(exc: BaseException) -> str:
    text = str(exc) if isinstance(exc, KinfuError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split()) or type(exc).__name__


def _folder_lock(outdir: Path):
    """One stage at a time writes into a recording's folder: the stages of one recording share its ownership
    record (.kinfu-manifest.json), which is read, updated and replaced by each writer. Recordings still run
    side by side. Outside a Dask worker (tests calling run_task directly) no lock is needed."""
    try:
        from distributed import Lock, get_worker

        get_worker()
    except (ImportError, ValueError):
        return contextlib.nullcontext()
    return Lock(f"kinfu-batch:{os.path.abspath(outdir)}")


def run_task(spec: StageSpec, rec, options: Mapping, previous: dict | None, force: bool, *upstream: dict,
             downstream: tuple = (), stale: tuple = (), elsewhere: tuple = ()) -> dict:
    """One (recording, stage) on a worker: blocked when a needed stage did not finish, skipped when its
    outputs are current (same input fingerprint, outputs unchanged since recorded), else run. Never raises:
    a failure is the entry's one-line `error`. `rec` is the plan's PlanRecording. downstream: (spec, recording) of
    the plan's tasks that read this one's outputs, directly or not: when the stage is redone, their outputs of an
    earlier run are removed first (kinfu's, unchanged since), so that a run stopped before they are redone (Ctrl-C,
    a killed worker) leaves them missing rather than complete-looking beside outputs they were not made from.
    stale: the specs of the stages that read this one's outputs but that the recording does not run (an earlier
    plan ran them): their outputs in its folder are removed too when the stage is redone (or fails, or is blocked),
    each said in a warning (they would never be redone, and sat beside the new outputs they were not made from).
    A redone stage also removes its own outputs of an earlier run that this run does not write (a plot or viewer
    file whose option is now off, the combined viewer file under the name the earlier plan gave: _unwritten), and
    those of the downstream stages. elsewhere: (spec, recording) of other recordings' stages that may have read
    this one's outputs through a link and that they no longer run (stale_elsewhere): their outputs are named in a
    warning, not removed (the manifest does not record which recording a link named)."""
    t0 = time.perf_counter()
    entry = {"status": "failed", "seconds": 0.0, "error": None, "fingerprint": None, "outputs": None,
             "numbers": {}, "warnings": []}
    if bad := [u["stage"] if u.get("folder") in (None, str(rec.output)) else f"{u['stage']} of {u['folder']}"
               for u in upstream if u.get("status") not in DONE]:
        return {**entry, "status": "blocked", "error": f"needs {', '.join(bad)}, which did not finish",
                "stage": spec.name, "folder": str(rec.output), "warnings": _drop_stale(spec, rec, stale, elsewhere)}
    removed = None  # the warnings of the removals before the stage ran, once done
    try:
        outdir, outputs = rec.output, spec.outputs_of(rec)
        if not force and (edited := [c for rel in spec.claims_of(rec) for c in changed_since_written(outdir / rel)]):
            raise KinfuError(f"{', '.join(edited)} in {outdir} changed since kinfu wrote it: the {spec.name} outputs "
                             f"are no longer current, and redoing the stage would replace the file; move it away, "
                             f"or force the run to replace it")
        fp = input_fingerprint(spec.name, spec.input_paths(rec), options)
        if (not force and previous and previous.get("status") in DONE and previous.get("fingerprint") == fp
                and output_stats(outdir, outputs) == previous.get("outputs")):
            return {**entry, "numbers": previous.get("numbers"), "status": "skipped", "fingerprint": fp,
                    "outputs": previous["outputs"], "stage": spec.name, "folder": str(rec.output),
                    "warnings": [w for w in previous.get("warnings") or () if not _REMOVAL.match(w)]}
        with contextlib.suppress(Exception):  # one numba thread per worker thread: no oversubscription
            import numba

            numba.set_num_threads(1)
        with _folder_lock(outdir):  # another run writing this folder sees the removal and the new outputs together
            removed = _drop_unwritten(spec, rec, options, outdir)
            for later_spec, later_rec in downstream:  # redone in this run, after this stage (they wait for it)
                removed += _drop_unwritten(later_spec, later_rec, later_rec.stage_options(later_spec.name), outdir,
                                           say_kept=False)  # that stage says it when it runs, or fails
                _remove_outputs(later_spec, later_rec)
            removed += _drop_later(spec, rec, stale) + _left_elsewhere(spec, rec, elsewhere)
            done = spec.run(rec, options, force)
        stats = output_stats(outdir, outputs)
        if stats is None:
            raise KinfuError(f"{spec.name} finished without writing {', '.join(outputs)}")
        entry.update(status="ok", fingerprint=fp, outputs=stats, numbers=done.numbers,
                     warnings=[*done.warnings, *removed])
    except Exception as exc:  # recorded in the manifest; the other recordings go on
        entry["error"] = _one_line(exc)
        entry["warnings"] = (_drop_stale(spec, rec) if removed is not None else _drop_stale(spec, rec, stale, elsewhere)
                             ) + (removed or [])
    entry["seconds"] = round(time.perf_counter() - t0, 3)
    entry["stage"], entry["folder"] = spec.name, str(rec.output)
    return entry


def _drop_stale(spec: StageSpec, rec, stale: tuple = (), elsewhere: tuple = ()) -> list[str]:
    """Remove the outputs an earlier run of a stage that failed or was blocked left (kinfu's, unchanged since), and
    those of the `stale` stages made from them (run_task): they would sit, complete-looking, beside the other
    stages' new results (a segment of the old fuse beside the new one). Returns the warnings that say so ([] when
    there were none), and, when some were removed, the one naming the outputs `elsewhere` that may have been made
    from them."""
    with _folder_lock(rec.output):
        gone, kept = _remove_outputs(spec, rec)
        own = _removal_warning(spec, rec.output, gone, kept, "they would not match this run's other results")
        return own + _drop_later(spec, rec, stale) + (_left_elsewhere(spec, rec, elsewhere) if gone else [])


def _drop_later(spec: StageSpec, rec, stale: tuple) -> list[str]:
    """Remove the outputs of the `stale` stages (read `spec`'s outputs, not run for this recording: run_task) in the
    recording's folder; returns the warnings that say so."""
    return [w for later in stale for w in _removal_warning(
        later, rec.output, *_remove_outputs(later, rec),
        f"{later.name} is not in this plan, and they were made from an earlier run's {spec.name} outputs")]


def _drop_unwritten(spec: StageSpec, rec, options: Mapping, base: Path, say_kept: bool = True) -> list[str]:
    """Remove the stage's outputs of an earlier run that this run of it does not write (_unwritten): a views.png
    beside new views.json it does not show. Returns the warning that says so (and what was kept, unless not
    `say_kept`), its paths named from `base`."""
    gone, kept = _remove_paths(rec, _unwritten(spec, rec, options))
    return _removal_warning(spec, base, gone, kept if say_kept else [],
                            f"this run of {spec.name} does not write them, and they would not match its outputs")


def _left_elsewhere(spec: StageSpec, rec, elsewhere: tuple) -> list[str]:
    """The warnings naming the outputs of the `elsewhere` stages (other recordings' stages not run, that may have
    read `spec`'s outputs of this recording through a link: run_task) that are there. They are left: the manifest
    does not record which recording's outputs a link named (diff's `before`)."""
    found: dict[str, list[str]] = {}
    for later, other in elsewhere:
        found.setdefault(later.name, []).extend(str(other.output / p) for p in _paths(later, other)
                                                if (other.output / p).exists())
    return [f"the {name} outputs of an earlier run: left {', '.join(paths)}: this plan no longer runs {name} there, "
            f"and the manifest does not record whether they were made from this recording's earlier {spec.name} "
            f"outputs, which this run replaced or removed; if they were, they match nothing: remove them"
            for name, paths in found.items() if paths]


#: how a warning about an earlier run's outputs removed begins (a skipped stage does not repeat it: nothing was removed)
_REMOVAL = re.compile(r"the \S+ outputs of an earlier run: ")


def _removal_warning(spec: StageSpec, base: Path, gone: list[Path], kept: list[Path], why: str) -> list[str]:
    """The warning saying which of the stage's outputs of an earlier run were removed and which were kept, and why
    they were removed ([] when nothing was there); paths are named from the folder `base` (the recording's), or in
    full when outside it (another recording's)."""
    def names(paths):
        return ", ".join(sorted({_named_from(p, base) for p in paths}))

    done = ([f"removed {names(gone)}"] if gone else []) + ([
        f"kept {names(kept)} (not written by kinfu, or changed since it was)"] if kept else [])
    return [f"the {spec.name} outputs of an earlier run: {', '.join(done)}: {why}"] if done else []


def _named_from(path: Path, base: Path) -> str:
    rel = os.path.relpath(path, base)
    return str(path) if rel == os.pardir or rel.startswith(os.pardir + os.sep) else rel


def _resolves(spec: StageSpec, links: Mapping) -> bool:
    """Whether the stage's claims are known with these links: fixed ones, or those its links name."""
    return not callable(spec.claims) or all(link in links for link in spec.links)


def _paths(spec: StageSpec, rec) -> tuple[str, ...]:
    """Where the stage writes in the recording's folder: its claims under the names this plan gives (when it gives
    them) and under those the earlier run's plan gave (rec.earlier: a combined viewer file renamed or dropped
    since), and its extras."""
    now = spec.claims_of(rec) if _resolves(spec, rec.links) else ()
    before = () if not callable(spec.claims) or not _resolves(spec, rec.earlier) else tuple(
        c for named in itertools.product(*(rec.earlier[link] for link in spec.links))
        for c in spec.claims_of(replace(rec, links={**rec.links, **dict(zip(spec.links, named))})))
    return tuple(dict.fromkeys((*now, *before, *spec.extra_files())))


def _unwritten(spec: StageSpec, rec, options: Mapping) -> tuple[str, ...]:
    """The stage's paths that a run of it with `options` does not write: its extras whose option is off, and its
    claims under the names the earlier run's plan gave and this one does not."""
    now = {*(spec.claims_of(rec) if _resolves(spec, rec.links) else ()), *spec.extra_files(options)}
    return tuple(p for p in _paths(spec, rec) if p not in now)


def _remove_outputs(spec: StageSpec, rec) -> tuple[list[Path], list[Path]]:
    """Remove the stage's outputs (_paths: its claims, and the plots and viewer files it writes when asked) in the
    recording's folder that kinfu wrote and nobody changed since (_remove_paths). Returns (removed, kept) paths."""
    return _remove_paths(rec, _paths(spec, rec))


def _remove_paths(rec, rels) -> tuple[list[Path], list[Path]]:
    """Remove what kinfu wrote and nobody changed since at these paths of the recording's folder: an output holding a
    file edited since stays whole (the user's now); a user's file in a kinfu folder stays where it is, kinfu's files
    beside it go (core.ownership.remove_written). Returns (removed, kept) paths."""
    gone: list[Path] = []
    kept: list[Path] = []
    for rel in rels:
        path = rec.output / rel
        if edited := changed_since_written(path):  # a user's edit: the output stays whole, neither used nor removed
            kept += [path.parent / e for e in edited]
            continue
        removed, left = remove_written(path)
        gone += removed
        kept += left
    return gone, kept


def _user_entries(folder: Path) -> list[str]:
    """Names in `folder` other than batch's lock file and kinfu's temporaries."""
    return sorted(e.name for e in folder.iterdir() if e.name != LOCK_NAME and not TEMPORARY_NAME.match(e.name))


def claim_folder(folder: Path, inputs, force: bool, where: str = "") -> None:
    """The rule of the single commands' outputs for a folder batch writes into: refused when it is or holds an
    input, and, unless `force`, when it exists holding entries without kinfu's ownership record
    (core.ownership: a folder batch wrote into holds one). An empty folder is fine. `where` prefixes the error."""
    empty = folder.is_dir() and not _user_entries(folder)
    try:
        claim_output(folder, inputs, force=force or empty)
    except KinfuError as exc:
        raise type(exc)(f"{where}{exc.detail}") from None


def check_output_folders(plan: Plan, force: bool) -> None:
    """The batch output folder and every recording's output folder (`claim_folder`), before anything is written."""
    inputs = [r.path for r in plan.recordings]
    try:
        claim_folder(plan.output, inputs, force)
    except KinfuError as exc:
        raise plan.output_error(exc) from None
    for rec in plan.recordings:
        claim_folder(rec.output, inputs, force, f"{plan.source}: {rec.entry}: ")


def check_before_work(plan: Plan, table: Mapping[str, StageSpec], force: bool) -> None:
    """Options of every (recording, stage), every output path, then every output folder, before anything is
    written (the command checks before it takes the lock, whose file would go into a user's folder)."""
    inputs = [r.path for r in plan.recordings]
    try:
        claim_output(plan.output / MANIFEST_NAME, inputs, force=force)
        # a recording that is a folder (a ROS 2 bag) is one input: the outputs written inside it would join it
        refuse_inside_folders(plan.output, [f for r in plan.recordings for f in recording_folders(r.path)])
    except KinfuError as exc:  # named as the plan file or the caller gave the folder
        raise plan.output_error(exc) from None
    for rec in plan.recordings:
        for s in rec.stages:
            spec = table[s]
            try:
                spec.check(rec, rec.stage_options(s))
            except KinfuError as exc:
                raise ConfigError(f"{plan.source}: {rec.entry}: {s}: {exc}") from None
            for rel in spec.claims_of(rec):  # a stage's file, not batch's --output: named with its plan entry
                try:
                    claim_output(rec.output / rel, inputs, force=force)
                except KinfuError as exc:
                    raise type(exc)(f"{plan.source}: {rec.entry}: {s}: {exc.detail}") from None
    check_output_folders(plan, force)  # after the paths: a user's file where a stage writes is named itself


def _mark_folders(plan: Plan) -> None:
    """Mark the existing output folders as kinfu's (claimed by this run, forced too; core.ownership): a later run
    takes them back, the user's files in them kept, without being forced."""
    for folder in (plan.output, *(rec.output for rec in plan.recordings)):
        if folder.is_dir():
            mark_folder_output(folder)


def task_graph(plan: Plan, table: Mapping[str, StageSpec]) -> dict[tuple[int, str], list[tuple[int, str]]]:
    """(recording index, stage) -> the tasks it runs after (its needs and wants in the recording, and the other
    recordings' stages it reads), in pipeline order: every task after the tasks it runs after."""
    graph: dict = {}
    for s in plan.stages:
        for i, rec in enumerate(plan.recordings):
            if s in rec.stages:
                spec = table[s]
                graph[(i, s)] = [(i, n) for n in (*spec.needs, *spec.wants) if n in rec.stages]
                graph[(i, s)] += [(j, n) for stage, j, n in rec.after if stage == s]
    return graph


def dependents(graph: Mapping) -> dict[tuple[int, str], list[tuple[int, str]]]:
    """task -> every task that runs after it, directly or through others (task_graph's order)."""
    out: dict = {task: [] for task in graph}
    for task in reversed(list(graph)):  # a task's dependents are complete before the tasks it runs after
        for before in graph[task]:
            for t in (task, *out[task]):
                if t not in out[before]:
                    out[before].append(t)
    return out


def stale_stages(table: Mapping[str, StageSpec], rec, stage: str) -> tuple[StageSpec, ...]:
    """The stages of the table that read `stage`'s outputs, directly or not, and that the recording does not run: an
    earlier plan's, whose outputs in its folder were made from the outputs `stage` replaces. The batch layout fixes
    where each writes; a stage whose paths the plan names (the combined viewer file) is there when the earlier run's
    manifest named them (rec.earlier), else it has none to find, and is left out."""
    return tuple(table[t] for t in stage_dependents(table)[stage]
                 if t not in rec.stages and (not callable(table[t].claims) or (bool(table[t].links) and _resolves(
                     table[t], rec.earlier))))


def stale_elsewhere(table: Mapping[str, StageSpec], plan: Plan, i: int, stage: str) -> tuple:
    """(spec, recording) of the stages of the plan's other recordings that may read recording i's `stage` outputs
    through a link an earlier plan named (StageSpec.reads_others: diff's `before`, another recording's fuse) and
    that this plan does not run for them: their outputs there may have been made from the outputs `stage`
    replaces."""
    return tuple((table[t], other) for j, other in enumerate(plan.recordings) if j != i
                 for t in table if stage in table[t].reads_others and t not in other.stages)


def with_earlier(plan: Plan, table: Mapping[str, StageSpec], manifest_path: Path) -> Plan:
    """The plan, each recording with the paths earlier plans named for it that the earlier run's manifest.json
    records (PlanRecording.earlier: the combined viewer files), read only when kinfu wrote that manifest and nobody
    changed it since. A path is taken only directly in the recording's folder, under a name no stage's fixed layout
    uses and not hidden: a manifest names nothing else kinfu would remove."""
    links = read_links(manifest_path) if written_by_kinfu(manifest_path) else {}
    fixed = {Path(p).parts[0] for s in table.values() if not callable(s.claims) for p in (*s.claims, *s.extra_files())}
    recs = []
    for rec in plan.recordings:
        named = {k: kept for k, paths in links.get(str(rec.output), {}).items() if (kept := tuple(
            p for p in paths if os.path.normpath(p.parent) == os.path.normpath(rec.output) and p.name not in fixed
            and not p.name.startswith(".")))}
        recs.append(replace(rec, earlier=named))
    return replace(plan, recordings=recs)


def run_plan(plan: Plan, table: Mapping[str, StageSpec], engine: Engine, *, force: bool = False,
             quiet: bool = False, on_entry: Callable[[dict], None] | None = None, redo: bool = False) -> dict:
    """Submit the plan's task graph, write manifest.json after each finished task; returns the manifest.
    force: redo every stage and write over outputs kinfu did not write; redo: only redo every stage."""
    manifest_path = plan.output / MANIFEST_NAME
    previous = {} if force or redo else read_previous(manifest_path)
    plan = with_earlier(plan, table, manifest_path)  # what the earlier run wrote under names its plan gave
    _mark_folders(plan)
    run_id = uuid.uuid4().hex[:8]
    futures: dict = {}
    where: dict = {}
    needs = task_graph(plan, table)
    later = dependents(needs)
    for (i, s), deps in needs.items():  # pipeline order: what a task waits for is submitted before it
        rec = plan.recordings[i]
        downstream = tuple((table[t], plan.recordings[j]) for j, t in later[(i, s)])
        fut = engine.client.submit(run_task, table[s], rec, rec.stage_options(s), previous.get((str(rec.output), s)),
                                   force, *(futures[d] for d in deps), downstream=downstream,
                                   stale=stale_stages(table, rec, s), elsewhere=stale_elsewhere(table, plan, i, s),
                                   key=f"kinfu-{s}-{i}-{run_id}", pure=False)
        futures[(i, s)] = fut
        where[fut.key] = (i, s)
    from dask.distributed import as_completed

    pending = list(futures.values())
    entries: dict = {}
    doc = build_manifest(plan, entries, engine.description)
    write_manifest(manifest_path, doc)
    try:
        for fut in progress(as_completed(pending, loop=engine.client.loop), total=len(pending), desc="batch",
                            quiet=quiet, unit="task"):
            i, s = where[fut.key]
            try:
                entry = fut.result()
            except Exception as exc:  # the worker died or the task could not be run
                entry = {"status": "failed", "seconds": 0.0, "error": _one_line(exc), "fingerprint": None,
                         "outputs": None, "numbers": {}, "warnings": [], "stage": s}
            entry.pop("stage", None)
            entry.pop("folder", None)
            fut.release()  # a finished task's result is not kept on a worker: a lost worker never re-runs it
            entries[(i, s)] = entry
            doc = build_manifest(plan, entries, engine.description)
            write_manifest(manifest_path, doc)
            if on_entry is not None:
                on_entry({"recording": str(plan.recordings[i].path), "stage": s, **entry})
    except BaseException:
        with contextlib.suppress(Exception):
            engine.client.cancel(pending)
        raise
    finally:
        _mark_folders(plan)  # the folders the stages created
    return doc
