"""The batch plan: which recordings go through which stages with which options (TOML or YAML).

    output = "out/batch"                      # optional: the command line's output wins
    stages = ["fuse", "poi", "nbv", "segment"]
    viz = "viewer.mcap"                       # optional: one viewer file per recording (the command line wins)
    recordings = ["sessions/*.mcap", {path = "lab/day2.bag", output = "day2", options = {fuse = {end = 6}}},
                  {path = "lab/day3.bag", stages = ["fuse", "diff"], before = "lab/day2.bag"}]
    [options.fuse]
    voxel-size = 0.02

A recording entry may replace the plan's `stages` with its own, name the `before` of its diff (another
recording of the plan named by its output folder or path, whose fused volume is used and which is fused first,
or a volume.npz / ternary.npz) and the
`ground-truth` of its evaluations (default: the ground_truth folder beside the recording, kinfu synth's
layout). Paths are relative to the plan file. Everything is checked before any work: unknown keys or stages, a
stage without the stages it needs, a stage without its inputs (diff without `before`, an evaluation without
ground truth), a path that does not exist or a glob that matches nothing, options for a stage that no
recording runs (an entry's options: that the recording does not run), and two recordings that would write to
the same output folder are one-line errors naming the plan entry.
"""

from __future__ import annotations

import glob
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from kinfu_cli.core.errors import ConfigError, KinfuError
from kinfu_cli.batch.stages import StageSpec

_TOP_KEYS = {"output", "stages", "options", "recordings", "viz"}
_ENTRY_KEYS = {"path", "output", "options", "stages", "before", "ground-truth"}
VIZ_STAGE = "viz"  # the stage combining a recording's viewer files; never listed, set by `viz`


@dataclass(frozen=True)
class PlanRecording:
    """One recording of the plan: where it is, its output folder, its options per stage, its plan entry."""

    path: Path
    output: Path
    options: dict[str, dict]
    entry: str
    stages: tuple[str, ...] = ()
    links: dict[str, Path] = field(default_factory=dict)
    after: tuple[tuple[str, int, str], ...] = ()  # (stage, other recording's index, its stage) it runs after
    # link -> the paths earlier plans gave it that the previous run's manifest.json records (the combined viewer
    # files): where earlier runs wrote under names their plans gave (batch.engine removes them when stale; run_plan)
    earlier: dict[str, tuple[Path, ...]] = field(default_factory=dict)

    def stage_options(self, stage: str) -> dict:
        return self.options.get(stage, {})


@dataclass(frozen=True)
class Plan:
    source: Path
    output: Path
    stages: list[str]  # every stage some recording has, in pipeline order
    recordings: list[PlanRecording] = field(default_factory=list)
    viz: str | None = None
    output_from_plan: bool = False  # `output` is the plan's key (else the caller's `output` parameter)

    def output_error(self, exc: KinfuError) -> KinfuError:
        """`exc`, about the output folder, naming where the folder came from: the plan file's `output` key, or the
        caller's `output` parameter."""
        if self.output_from_plan:
            return type(exc)(f"{self.source}: output: {exc.detail}")
        return type(exc)(exc.detail, parameter="output")


def _fail(source: Path, where: str, what: str) -> ConfigError:
    return ConfigError(f"{source}: {where}: {what}")


def _read(source: Path) -> dict:
    try:
        text = source.read_text()
    except OSError as exc:
        raise ConfigError(f"{source}: cannot read the plan ({exc.strerror})") from None
    suffix = source.suffix.lower()
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{source}: not valid TOML ({exc})") from None
    elif suffix in (".yaml", ".yml"):
        import yaml  # PyYAML comes with dask

        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{source}: not valid YAML ({' '.join(str(exc).split())})") from None
    else:
        raise ConfigError(f"{source}: expected a .toml, .yaml or .yml plan")
    if not isinstance(doc, dict):
        raise ConfigError(f"{source}: expected a table/mapping at the top")
    return doc


def _normalise_options(source: Path, where: str, value, table: Mapping[str, StageSpec]) -> dict[str, dict]:
    """{stage: {option-name: value}} with option names in their flag spelling (voxel_size -> voxel-size); the
    stage's file options resolved against the plan's folder."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _fail(source, where, "expected a table of stages")
    out = {}
    for stage, opts in value.items():
        if stage not in table:
            raise _fail(source, f"{where}.{stage}", f"unknown stage (known: {', '.join(table)})")
        if not isinstance(opts, dict):
            raise _fail(source, f"{where}.{stage}", "expected a table of options")
        out[stage] = {str(k).replace("_", "-"): v for k, v in opts.items()}
        for key in table[stage].file_options:  # input files named by options: relative to the plan, as recordings
            value = out[stage].get(key)
            if isinstance(value, str):
                full = Path(os.path.normpath(value if os.path.isabs(value) else source.parent / value))
                if not full.exists():
                    raise _fail(source, f"{where}.{stage}.{key}", f"{value}: no such file")
                out[stage][key] = str(full)
    return out


def _expand(source: Path, where: str, pattern: str) -> list[Path]:
    base = source.parent
    full = os.path.normpath(pattern if os.path.isabs(pattern) else base / pattern)
    if glob.has_magic(pattern):
        found = sorted(Path(p) for p in glob.glob(full, recursive=True))
        if not found:
            raise _fail(source, where, f"{pattern!r} matches nothing")
        return found
    if not Path(full).exists():
        raise _fail(source, where, f"{pattern}: no such file or folder")
    return [Path(full)]


def _default_output(source: Path, path: Path) -> Path:
    """The recording's path relative to the plan without its suffix (sessions/day1.mcap -> sessions/day1);
    a recording outside the plan's folder: its name without suffix."""
    try:
        rel = Path(os.path.abspath(path)).relative_to(os.path.abspath(source.parent))
    except ValueError:
        rel = Path(path.name)
    return rel.with_suffix("") if rel.suffix else rel


def _stage_list(source: Path, where: str, stages, table: Mapping[str, StageSpec]) -> list[str]:
    """A checked list of stages in pipeline order: known, listed once, with the stages they need."""
    if isinstance(stages, str):
        stages = [stages]
    if not isinstance(stages, list) or not stages or not all(isinstance(s, str) for s in stages):
        raise _fail(source, where, f"expected a non-empty list of stage names ({', '.join(_listable(table))})")
    for s in stages:
        if s not in table or s == VIZ_STAGE:
            hint = " (it is set by viz = \"FILE.mcap\")" if s == VIZ_STAGE else ""
            raise _fail(source, where, f"unknown stage {s!r} (known: {', '.join(_listable(table))}){hint}")
        if missing := [n for n in table[s].needs if n not in stages]:
            raise _fail(source, where, f"{s} needs {', '.join(missing)}: add it to the list")
    if len(set(stages)) != len(stages):
        raise _fail(source, where, "a stage is listed twice")
    return [s for s in table if s in stages]


def _listable(table) -> list[str]:
    return [s for s in table if s != VIZ_STAGE]


def _recordings(source: Path, doc: dict, output: Path, table, stages: list[str]) -> list[tuple[PlanRecording, dict]]:
    entries = doc.get("recordings")
    if isinstance(entries, str):
        entries = [entries]
    if not isinstance(entries, list) or not entries:
        raise _fail(source, "recordings", "expected a non-empty list of paths, globs or {path, output, options}")
    out: list[tuple[PlanRecording, dict]] = []
    for i, e in enumerate(entries):
        where = f"recordings[{i}]"
        if isinstance(e, str):
            e = {"path": e}
        if not isinstance(e, dict) or not isinstance(e.get("path"), str):
            raise _fail(source, where, "expected a path or glob, or a table with 'path'")
        if unknown := set(e) - _ENTRY_KEYS:
            raise _fail(source, where, f"unknown key(s) {', '.join(sorted(unknown))} "
                                       f"(known: {', '.join(sorted(_ENTRY_KEYS))})")
        paths = _expand(source, where, e["path"])
        if e.get("output") is not None and (isinstance(e["output"], bool) or not isinstance(e["output"], (str, int))):
            raise _fail(source, where, f"output {e['output']!r}: expected a folder name inside the output folder")
        if e.get("output") is not None and len(paths) > 1:
            raise _fail(source, where, f"'output' names one folder but {e['path']!r} matches {len(paths)} recordings")
        opts = _normalise_options(source, f"{where}.options", e.get("options"), table)
        own = _stage_list(source, f"{where}.stages", e["stages"], table) if "stages" in e else stages
        for p in paths:
            rel = Path(str(e["output"])) if e.get("output") is not None else _default_output(source, p)
            if rel.is_absolute() or ".." in rel.parts or str(rel) in ("", "."):
                raise _fail(source, where, f"output {str(rel)!r}: expected a folder name inside the output folder")
            out.append((PlanRecording(path=p, output=output / rel, options=opts, entry=f"{where} {p}",
                                      stages=tuple(own)), e))
    seen: dict[Path, PlanRecording] = {}
    for r, _ in out:
        key = Path(os.path.normpath(r.output))
        if key in seen:
            raise _fail(source, r.entry.split(" ")[0],
                        f"{r.path} and {seen[key].path} ({seen[key].entry.split(' ')[0]}) would both write to "
                        f"{r.output}; give one of them an 'output'")
        seen[key] = r
    for key, r in seen.items():  # one recording's folder inside another's: its outputs would replace the other's
        if (outer := next((seen[a] for a in key.parents if a in seen), None)) is not None:
            raise _fail(source, r.entry.split(" ")[0],
                        f"the output folder of {r.path}, {r.output}, lies inside that of {outer.path} "
                        f"({outer.entry.split(' ')[0]}), {outer.output}; give them folders side by side")
    return out


def _before(source: Path, i: int, rec: PlanRecording, value, recs: list[PlanRecording], out: Path
            ) -> tuple[Path, tuple]:
    """The volume a diff compares with and the task it waits for: another recording of the plan, named by its
    output folder or its path (its fused volume, after its fuse), or a volume file."""
    where = rec.entry.split(" ")[0]
    if not isinstance(value, str) or not value.strip():
        raise _fail(source, where, "before: expected a recording of this plan (its output folder or path) or the "
                                   "path of a volume.npz")
    full = Path(os.path.normpath(value if os.path.isabs(value) else source.parent / value))
    named = [j for j, o in enumerate(recs) if os.path.normpath(o.output) == os.path.normpath(out / value)]
    named = named or [j for j, o in enumerate(recs) if os.path.abspath(o.path) == os.path.abspath(full)]
    if len(named) > 1:
        raise _fail(source, where, f"before: {value} is the path of {len(named)} recordings of this plan; name "
                                   "one by its output folder")
    if named:
        (j,) = named
        other = recs[j]
        if j == i:
            raise _fail(source, where, "before: names the recording itself")
        if "fuse" not in other.stages:
            raise _fail(source, where, f"before: {value} is not fused in this plan (its stages lack fuse)")
        return other.output / "fuse" / "volume.npz", (("diff", j, "fuse"),)
    if full.is_file() and full.suffix == ".npz":
        return full, ()
    raise _fail(source, where, f"before: {value}: no such recording in this plan nor volume file (.npz)")


def _links(source: Path, pairs: list[tuple[PlanRecording, dict]], viz: str | None, output: Path
           ) -> list[PlanRecording]:
    """Each recording with its links resolved (diff's before, the evaluations' ground truth, the viewer file)
    and a check that every stage it has finds its inputs."""
    recs = [r for r, _ in pairs]
    out = []
    for i, (rec, e) in enumerate(pairs):
        where = rec.entry.split(" ")[0]
        links: dict[str, Path] = {}
        after: tuple = ()
        if "before" in e:
            if "diff" not in rec.stages:
                raise _fail(source, where, "before: given, but diff is not among the recording's stages")
            links["before"], after = _before(source, i, rec, e["before"], recs, output)
        elif "diff" in rec.stages:
            raise _fail(source, where, "diff needs 'before' (a recording of this plan or a volume.npz); or give "
                                       "this recording its own 'stages' without diff")
        evals = [s for s in rec.stages if s.startswith("eval-")]
        if "ground-truth" in e:
            gt = e["ground-truth"]
            if not isinstance(gt, str) or not (p := Path(os.path.normpath(source.parent / gt))).is_dir():
                raise _fail(source, where, f"ground-truth: {gt}: no such folder (a kinfu synth ground_truth/)")
            links["ground_truth"] = p
        elif evals:
            p = rec.path.parent / "ground_truth"
            if not p.is_dir():
                raise _fail(source, where, f"{', '.join(evals)} need(s) ground truth: no {p} (kinfu synth's layout); "
                                           "give 'ground-truth', or this recording's own 'stages' without them")
            links["ground_truth"] = p
        stages = rec.stages
        if viz is not None and any(s in VIZ_PARTS for s in stages):
            links["viz"] = rec.output / viz
            stages = (*stages, VIZ_STAGE)
        out.append(PlanRecording(rec.path, rec.output, rec.options, rec.entry, stages, links, after))
    return out


def _check_options_used(source: Path, common: dict[str, dict], recs: list[PlanRecording]) -> None:
    """Options for a stage that would never run are a mistake (a stage left out of `stages`, options under the
    wrong entry), not options kept for later: they were neither checked nor used, so refuse them. The plan's
    common options need some recording with the stage; an entry's options need the stage in its own list."""
    def keys(opts: dict) -> str:
        return ", ".join(opts) or "an empty table"

    every = {s for r in recs for s in r.stages}
    for stage, opts in common.items():
        if stage not in every:
            raise _fail(source, f"options.{stage}", f"options ({keys(opts)}) for a stage that no recording of the "
                                                     f"plan runs (stages: {', '.join(sorted(every))}): add {stage} "
                                                     f"to 'stages' or remove its options")
    for rec in recs:
        for stage, opts in rec.options.items():
            if stage not in rec.stages:
                where = rec.entry.split(" ")[0]
                raise _fail(source, f"{where}.options.{stage}",
                            f"options ({keys(opts)}) for a stage that {rec.path} does not run (its stages: "
                            f"{', '.join(s for s in rec.stages if s != VIZ_STAGE)}): add {stage} to its "
                            f"stages or remove its options")


#: stages that write a viewer file of their own (the combined file of a recording is made from them)
VIZ_PARTS = ("fuse", "poi", "nbv", "segment")


def _viz_name(source: Path, value) -> str | None:
    if value is None:
        return None
    if (not isinstance(value, str) or not value.endswith(".mcap") or Path(value).name != value
            or value in (".mcap",)):
        raise _fail(source, "viz", f"expected a file name ending .mcap (one per recording, in its folder), got "
                                   f"{value!r}")
    return value


def load_plan(source: str | os.PathLike, table: Mapping[str, StageSpec], output: str | os.PathLike | None = None,
              viz: str | None = None) -> Plan:
    """Read and check the plan at `source` against the stage table; `output` and `viz` override the plan's."""
    source = Path(source)
    doc = _read(source)
    if unknown := set(doc) - _TOP_KEYS:
        raise _fail(source, ", ".join(sorted(unknown)), f"unknown key(s) (known: {', '.join(sorted(_TOP_KEYS))})")
    stages = _stage_list(source, "stages", doc.get("stages"), table)
    if output is None:
        if not isinstance(doc.get("output"), str) or not doc["output"].strip():
            raise _fail(source, "output", "no output folder: give 'output' in the plan or on the command line")
        out = Path(doc["output"])
        out = out if out.is_absolute() else Path(os.path.normpath(source.parent / out))
    else:
        out = Path(output)
    viz = _viz_name(source, viz if viz is not None else doc.get("viz"))
    if viz is not None and VIZ_STAGE not in table:
        raise _fail(source, "viz", "this stage table has no viewer stage")
    common = _normalise_options(source, "options", doc.get("options"), table)
    recs = _links(source, _recordings(source, doc, out, table, stages), viz, out)
    _check_options_used(source, common, recs)
    merged = []
    for r in recs:
        opts = {s: {**common.get(s, {}), **r.options.get(s, {})} for s in r.stages}
        if viz is not None:  # each stage writes its own viewer file; the viz stage combines them
            for s in VIZ_PARTS:
                if s in opts:
                    opts[s]["viz"] = True
        merged.append(PlanRecording(r.path, r.output, opts, r.entry, r.stages, r.links, r.after))
    every = {s for r in merged for s in r.stages}
    return Plan(source=source, output=out, stages=[s for s in table if s in every], recordings=merged, viz=viz,
                output_from_plan=output is None)
