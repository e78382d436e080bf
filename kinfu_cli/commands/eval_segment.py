"""`kinfu eval segment`: boundary precision / recall, BCE, object recall and over-/under-segmentation of a
segmentation against ground-truth labels (thesis ch. 4.1.2), or the PR-curve sweep on generated scenes."""

from __future__ import annotations

from pathlib import Path

import click

from kinfu_cli.commands._options import (Inapplicable, OutputPath, SWEEP_ONLY_OPTIONS, check_inapplicable,
                                         claim_outputs, comma_items, comma_values, force_option)
from kinfu_cli.commands._output import QUIET_HELP, emit
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.evaluation.segment_eval import (RGB_T_LCCP_VALUES, SWEEP_DEFAULT, SWEEP_VALUES, check_eval_numbers,
                                               default_sweep_values, evaluate_segments, label_names,
                                               sweep_segmentation)
from kinfu_cli.evaluation.segments import MATCHINGS
from kinfu_cli.evaluation.segment_tables import format_segment_table, format_sweep_table
from kinfu_cli.segmentation.segments import COLOR_DISTANCES

group = "eval"


def _listed(values) -> str:
    return ",".join(f"{v:g}" for v in values)


def _numbers(text: str, option: str, kind=float) -> list:
    try:
        vals = [kind(v) for v in comma_items(text, option)]
    except ValueError:
        raise ConfigError(f"{option} {text!r}: expected comma-separated numbers") from None
    if not vals:
        raise ConfigError(f"{option} {text!r}: expected at least one number")
    return vals


def read_beside(segments: Path, ground_truth: Path) -> list[Path]:
    """The files scoring reads beside the named ones (inputs too, never written over): a segment output's
    segments.json and segments.ply go together, a labels file's object names are in the changes.json beside it."""
    beside = []
    if segments.name in ("segments.json", "segments.ply"):
        beside += [segments.parent / "segments.json", segments.parent / "segments.ply"]
    if not ground_truth.is_dir():
        beside.append(ground_truth.parent / "changes.json")
    return beside


def check_options(params: dict) -> None:
    """What `kinfu eval segment` (scoring SEGMENTS) refuses with these options before it reads anything (kinfu
    batch checks a plan with it); ConfigError naming the parameter."""
    check_eval_numbers(*(params[k] for k in ("t_eval", "max_distance", "cover", "share", "matching")))


# the sweep's options scoring SEGMENTS does not use (commands._options.check_inapplicable)
INAPPLICABLE = (Inapplicable(tuple(SWEEP_ONLY_OPTIONS), lambda p: None if p["sweep"] else "without --sweep",
                             message="{flags}: needs --sweep (scoring SEGMENTS does not use it)", warn=False),)


@click.command("segment", short_help="Segmentation boundary P/R, BCE, object recall vs labels; --sweep: PR curves.")
@click.argument("segments", required=False, type=click.Path(path_type=Path))
@click.option("--ground-truth", "ground_truth", type=click.Path(path_type=Path), default=None,
              help="Labels file (.ply with a per-point integer 'label', or .npz points + labels such as kinfu "
                   "synth's per-voxel labels.npz), or a kinfu synth folder holding ground_truth/labels.ply or "
                   "labels.npz.")
@click.option("--t-eval", type=float, default=0.02, show_default=True,
              help="T_eval (m): neighbourhood radius and boundary matching distance.")
@click.option("--matching", type=click.Choice(MATCHINGS), default="assignment", show_default=True,
              help="Boundary matching: the maximum one-to-one matching within T_eval (what Martin et al.'s minimum "
                   "distance assignment gives), or greedy closest pairs first (the scorer before 2026-11-26).")
@click.option("--max-distance", type=float, default=0.015, show_default=True,
              help="A segmented point takes the label of the nearest ground-truth point within this (m); farther "
                   "points are not scored (and counted).")
@click.option("--cover", type=float, default=0.8, show_default=True,
              help="A true object is found when one segment holds this share of it (and it is that segment's "
                   "majority).")
@click.option("--share", type=float, default=0.2, show_default=True,
              help="Over-/under-segmentation: a piece is at least this share of a true region.")
@click.option("--sweep", is_flag=True, help="Instead: segment generated scenes over a range of one segmentation "
                                            "threshold and print / plot boundary PR per scene.")
@click.option("--sweep-parameter", default=SWEEP_DEFAULT[0], show_default=True,
              help="The segmentation threshold to sweep (a numeric kinfu segment parameter).")
@click.option("--sweep-values", default=None,
              help=f"Its values, comma-separated [default: t_lccp {_listed(SWEEP_VALUES['t_lccp'])} in chroma, "
                   f"{_listed(RGB_T_LCCP_VALUES)} in rgb (2 prunes nothing); t_ff {_listed(SWEEP_VALUES['t_ff'])}; "
                   f"others {_listed(SWEEP_DEFAULT[1])}].")
@click.option("--color-distance", type=click.Choice(COLOR_DISTANCES), default="chroma", show_default=True,
              help="Sweep: the colour distance of t_lccp / t_ff (as kinfu segment --color-distance; rgb is the "
                   "thesis').")
@click.option("--method", type=click.Choice(["lccp", "flood-fill"]), default=None,
              help="Segmentation method of the sweep [default: flood-fill for t_ff, else lccp].")
@click.option("--color", "color", default="mean,mode", show_default=True,
              help="Sweep: fuse each scene with these colour modes, comma-separated: mean (running mean, 'not "
                   "enhanced'), mode (mode filter), none (no colour: shape only).")
@click.option("--photometric/--no-photometric", default=True, show_default=True,
              help="Sweep: render the colour images with the simulator's auto-gain, white-balance jitter and "
                   "colour-depth misregistration (what the mode filter is for).")
@click.option("--scene", "layouts", default="objects", show_default=True,
              help="Sweep: generated scene layouts, comma-separated: objects, tabletop (kinfu synth --scene).")
@click.option("--scenes", default="0,1,2", show_default=True, help="Seeds of the generated scenes (--sweep).")
@click.option("--resolution", type=int, default=160, show_default=True,
              help="Sweep: voxels per 1.1 m (the objects scene's cube; tabletop scenes fuse 1.6 m at that voxel).")
@click.option("--plot", type=OutputPath(dir_okay=False, kind="image"), default=None,
              help="PNG: top view of the scored points coloured by consistency error; with --sweep the PR curves.")
@click.option("-o", "--output", type=OutputPath(dir_okay=False, kind="json"), default=None,
              help="Write the results as JSON here.")
@click.option("--json", "as_json", is_flag=True, help="Print the results JSON to stdout instead of the table.")
@click.option("--quiet", is_flag=True, help=QUIET_HELP)
@force_option
def command(segments: Path | None, ground_truth: Path | None, t_eval: float, matching: str, max_distance: float,
            cover: float, share: float, sweep: bool, sweep_parameter: str, sweep_values: str | None,
            color_distance: str, method: str | None, color: str, photometric: bool, layouts: str, scenes: str,
            resolution: int, plot: Path | None, output: Path | None, as_json: bool, quiet: bool, force: bool) -> None:
    """Score SEGMENTS (a kinfu segment output folder, its segments.ply, or a labels file) against
    --ground-truth labels: boundary precision / recall at T_eval on the T_eval neighbourhood graph (thesis
    eq. 4.16, a maximum one-to-one matching within T_eval; --matching greedy: closest pairs first), Bidirectional Consistency Error, object recall (one segment
    holds >= --cover of a true object), over-segmented objects and under-segmenting segments. Ground-truth
    labels reach the segmented points by nearest neighbour within --max-distance; unmatched points are
    counted, not scored.

    --sweep needs no SEGMENTS: it fuses the generated scenes (kinfu synth --scene objects, seeds --scenes)
    once per --color mode, segments each over --sweep-values of --sweep-parameter (t_lccp: LCCP colour
    pruning, t_ff: Flood Fill, as in the thesis' Figs. 4.10-4.11) and prints P/R, BCE and object recall per
    value (minimum BCE per scene as in the thesis' Table 4.3) and the means per colour mode; --plot draws
    the PR curves.

    \b
    Example:
      kinfu synth -o out/objects --scene objects --formats mcap
      kinfu fuse out/objects/recording.mcap -o out/objects_fused
      kinfu segment out/objects_fused/volume.npz -o out/objects_segments
      kinfu eval segment out/objects_segments --ground-truth out/objects/ground_truth/labels.ply --plot top.png
      kinfu eval segment --sweep --sweep-parameter t_ff --scenes 4,5 --plot pr.png -o sweep.json
    """
    if sweep:
        if segments is not None or ground_truth is not None:
            raise ConfigError("--sweep makes its own scenes: give no SEGMENTS nor --ground-truth")
        values = (_numbers(sweep_values, "--sweep-values") if sweep_values is not None
                  else default_sweep_values(sweep_parameter, color_distance))
        seeds = _numbers(scenes, "--scenes", int)
        colors, scene_layouts = comma_values(color, "--color"), comma_values(layouts, "--scene")
        if not 32 <= resolution <= 512:
            raise ConfigError(f"--resolution: expected 32..512 voxels, got {resolution}")
        claim_outputs({"output": output, "plot": plot}, [], force)
        doc = sweep_segmentation(seeds, sweep_parameter, values, method=method, colors=colors, layouts=scene_layouts,
                                 photometric=photometric, t_eval=t_eval, matching=matching,
                                 max_distance=max_distance, cover=cover, share=share, resolution=resolution,
                                 quiet=quiet, color_distance=color_distance)
        doc["warnings"] = []
        if plot is not None:
            from kinfu_cli.report.segment_eval_plot import plot_sweep_pr

            doc["plot"] = str(plot_sweep_pr(doc, plot))
        emit(doc, output, as_json, lambda d: format_sweep_table(d).splitlines(), quiet)
        return
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    if segments is None:
        raise ConfigError("expected SEGMENTS (a kinfu segment output folder or labelled cloud), or --sweep")
    if ground_truth is None:
        raise ConfigError("--ground-truth: a labels file is needed to score SEGMENTS")
    claim_outputs({"output": output, "plot": plot}, [segments, ground_truth, *read_beside(segments, ground_truth)],
                  force)
    result = evaluate_segments(segments, ground_truth, t_eval=t_eval, matching=matching, max_distance=max_distance,
                               cover=cover, share=share)
    doc = result.document
    if plot is not None:
        from kinfu_cli.report.segment_eval_plot import plot_segment_errors

        names = label_names(doc["input"]["ground_truth"]) | {o["object"]: o["name"] for o in doc["per_object"]}
        doc["plot"] = str(plot_segment_errors(result.points, result.point_errors, result.gt_labels, names, result.up,
                                              plot, title=f"{segments.name}: per-point consistency error "
                                                          f"(BCE {doc['bce']:.3f})"))
    emit(doc, output, as_json, lambda d: format_segment_table(d).splitlines(), quiet)
