"""`kinfu eval fusion`: reconstruction error and the paper's object measures (Table 1) against ground truth."""

from __future__ import annotations

from pathlib import Path

import click

from kinfu_cli.commands._options import OutputPath, claim_outputs, result_options
from kinfu_cli.commands._output import QUIET_HELP, emit
from kinfu_cli.evaluation.reconstruction import (DEFAULT_SPACING, DEFAULT_THRESHOLD, check_fusion_evaluation,
                                                 evaluate_fusion)
from kinfu_cli.evaluation.tables import format_fusion_tables
from kinfu_cli.report.eval_fusion_mesh import write_error_mesh
from kinfu_cli.sim.sampling import MAX_SAMPLES

group = "eval"


def check_options(params: dict) -> None:
    """What `kinfu eval fusion` refuses with these options before it reads anything (kinfu batch checks a plan
    with it); ConfigError naming the parameter."""
    check_fusion_evaluation(**{k: params[k] for k in ("threshold", "spacing", "margin", "min_height")})


@click.command("fusion", short_help="Reconstruction error and object measures (paper Table 1) vs ground truth.")
@click.argument("reconstruction", metavar="OUTDIR_OR_MESH", type=click.Path(path_type=Path))
@click.option("--ground-truth", "ground_truth", required=True, type=click.Path(path_type=Path),
              help="A `kinfu synth` ground_truth/ folder (or the recording folder holding it).")
@click.option("--state", type=click.Choice(["after", "before"]), default="after", show_default=True,
              help="Which true scene to compare with (before: the initial scan's scene and poses).")
@click.option("--threshold", type=float, default=DEFAULT_THRESHOLD, show_default=True,
              help="Distance (m) for precision / completeness.")
@click.option("--spacing", type=float, default=DEFAULT_SPACING, show_default=True,
              help=f"True-surface sample spacing (m); at most {MAX_SAMPLES:,} samples (and at least one) are drawn, "
                   "so a spacing beyond that is changed, with a warning giving both.")
@click.option("--margin", type=float, default=0.02, show_default=True,
              help="Points within this distance (m) of an object's true box are its points.")
@click.option("--min-height", type=float, default=0.005, show_default=True,
              help="Object points must be this high (m) above the fitted table plane.")
@click.option("--footprint", type=click.Choice(["rect", "pca"]), default="rect", show_default=True,
              help="Footprint axes: minimum-area rectangle or principal-axis extents.")
@click.option("--no-volume", is_flag=True, help="Ignore OUTDIR/volume.npz (no voxel counts).")
@click.option("--error-mesh", type=OutputPath(dir_okay=False, kind="geometry"), default=None,
              help="Also write the reconstruction coloured by its error (blue 0 .. red 2 x threshold; grey: not "
                   "evaluated) as this .ply.")
@result_options(json="Print the results JSON to stdout instead of tables.", quiet=QUIET_HELP)
def command(reconstruction: Path, ground_truth: Path, state: str, threshold: float, spacing: float, margin: float,
            min_height: float, footprint: str, no_volume: bool, error_mesh: Path | None, output: Path | None,
            as_json: bool, quiet: bool, force: bool) -> None:
    """Score a fused reconstruction against ground truth. OUTDIR_OR_MESH is a `kinfu fuse` output folder
    (mesh.ply, and volume.npz when present) or a mesh file in the ground truth's world frame.

    Prints: accuracy (reconstructed vertices -> true mesh) and completeness (true surface the cameras saw ->
    reconstruction) as mean / median / RMS / 95th percentile, and shares within --threshold; with a volume, the
    unknown / empty / occupied counts and how much of the true surface is known; per object the height above the
    table and the footprint's major / minor axes vs the truth, pooled into the paper's Table 1 (mean abs. error,
    st. dev.) printed beside the paper's rows.

    \b
    Example:
      kinfu fuse sample_data/tabletop/recording.mcap -o out/scan --end 5.5
      kinfu eval fusion out/scan --ground-truth sample_data/tabletop/ground_truth --state before
      kinfu eval fusion out/all/mesh.ply --ground-truth sample_data/tabletop --json -o fusion_eval.json
      kinfu eval fusion out/scan --ground-truth sample_data/tabletop --error-mesh out/scan_error.ply
    """
    # a mesh file's fused time window is read from the report.json beside it: an input too, never written over
    beside = [] if reconstruction.is_dir() else [reconstruction.parent / "report.json"]
    claim_outputs({"output": output, "error_mesh": error_mesh}, [reconstruction, ground_truth, *beside], force)
    result = evaluate_fusion(reconstruction, ground_truth, state=state, threshold=threshold, spacing=spacing,
                             margin=margin, min_height=min_height, footprint=footprint, use_volume=not no_volume,
                             quiet=quiet)
    doc = result.document
    if error_mesh is not None:
        write_error_mesh(error_mesh, result.reconstruction, result.score.vertex_distances, 2.0 * threshold)
        doc["input"]["error_mesh"] = str(error_mesh)
    emit(doc, output, as_json, lambda d: [format_fusion_tables(d)] + (
        [f"error-coloured mesh -> {error_mesh}"] if error_mesh is not None else []), quiet)
