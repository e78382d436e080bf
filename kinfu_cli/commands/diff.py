"""`kinfu diff`: what changed between two fused volumes of the same place, and how well POIs point at it."""

from __future__ import annotations

import json
from pathlib import Path

import click

from kinfu_cli.change.diff import DEFAULT_MIN_VOXELS, ChangeParams, diff_volumes
from kinfu_cli.change.noise import NOISE_SIGMAS
from kinfu_cli.change.outputs import CHANGE_ENTRIES, write_change_outputs
from kinfu_cli.evaluation.change_pois import score_pois_in_comparison
from kinfu_cli.commands._options import (Inapplicable, OutputPath, check_inapplicable, claim_outputs, force_option,
                                         volume_file)
from kinfu_cli.commands._output import option_warnings_first, print_warnings
from kinfu_cli.core.atomic import atomic_dir
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.volume_file import MAX_COORDINATE_M
from kinfu_cli.core.pois import poi_frame_warnings, read_pois
from kinfu_cli.core.progress import progress
from kinfu_cli.evaluation.poi import MATCH_RADIUS


def _percent(ratio: float | None) -> str:
    return "undefined" if ratio is None else f"{100 * ratio:.1f} %"


def _compared(overlap: dict) -> str:
    """How much of each volume's observed space was compared: the overlap alone hides a grid that crops one."""
    return (f"{100 * overlap['before']['compared_fraction']:.0f} % of before's and "
            f"{100 * overlap['after']['compared_fraction']:.0f} % of after's observed voxels")


def _lines(doc: dict, outdir: Path) -> list[str]:
    c = doc["counts"]
    lines = [f"{c['regions']['removed']} removed and {c['regions']['added']} added regions "
             f"(overlap {100 * doc['overlap']['fraction']:.0f} %, compared {_compared(doc['overlap'])}, "
             f"{sum(c['unknown_ignored'].values())} voxels "
             f"unknown in one volume ignored, {c['dropped_small_regions']} small regions dropped) "
             f"-> {outdir}/changes.json"]
    for r in doc["regions"][:15]:
        lines.append(f"  #{r['id']:<3} {r['kind']:<8} centroid ({', '.join(f'{v:.3f}' for v in r['centroid'])}) m  "
                     f"{r['volume_m3'] * 1e6:9.0f} cm^3  {r['voxels']} voxels")
    if len(doc["regions"]) > 15:
        lines.append(f"  ... {len(doc['regions']) - 15} more in changes.json")
    p = doc["pois"]
    if p is not None:
        scored = "" if p["pois_scored"] == p["pois"] else f" ({p['pois_scored']} scored)"
        lines.append(f"POIs vs changes (within {p['radius']:.2f} m): precision {_percent(p['precision'])}, "
                     f"recall {_percent(p['recall'])}, F1 {_percent(p['f1'])} "
                     f"(tp {p['tp']}, fp {p['fp']}, fn {p['fn']}; {p['pois']} POIs{scored}, {p['changes']} regions)")
    return lines


# --match-radius scores POIs: a warning without --pois (kinfu batch gives --pois only to the recordings that run
# poi, and a plan's diff options are common to all; commands._options.check_inapplicable)
INAPPLICABLE = (Inapplicable(("match-radius",), lambda p: None if p["pois_path"] else "without --pois",
                             "with --pois"),)


def change_params(p: dict) -> ChangeParams:
    """ChangeParams from the command's parsed options (click's parameter dict), checked with --match-radius: the
    one place that turns diff's options into library parameters, for the command and for `check_options`."""
    params = ChangeParams(margin=p["margin"], min_volume=p["min_volume"], noise_sigmas=p["noise_sigmas"])
    params.check()
    check_number(p["match_radius"], "match_radius", 0.0, MAX_COORDINATE_M, low_open=True, unit="m")
    return params


def check_options(params: dict) -> None:
    """What `kinfu diff` refuses with these options before it reads the volumes (kinfu batch checks a plan with
    it); ConfigError naming the parameter."""
    change_params(params)


@click.command("diff", short_help="Removed / added regions between two volumes of one place; POIs scored on them.")
@click.argument("before", type=click.Path(path_type=Path))
@click.argument("after", type=click.Path(path_type=Path))
@click.option("-o", "--output", "outdir", type=OutputPath(file_okay=False, kind="folder"), default=Path("diff"),
              show_default=True, help="Output folder.")
@click.option("--pois", "pois_path", default=None, type=click.Path(dir_okay=False, path_type=Path),
              help="pois.json from `kinfu poi`: score each POI against the changes found.")
@click.option("--match-radius", type=float, default=MATCH_RADIUS, show_default=True,
              help="A POI within this distance (m) of a change's nearest voxel is a true positive (paper: 0.20).")
@click.option("--margin", type=int, default=1, show_default=True,
              help="Pose noise tolerated, voxels: a change must lie this far from every surface of the other volume.")
@click.option("--noise-sigmas", type=float, default=NOISE_SIGMAS, show_default=True,
              help="Depth noise tolerated: a change must also lie this many standard deviations of the sensor's "
                   "depth noise (at its distance from the cameras in the trajectory.tum beside each volume) from "
                   "the other volume's surfaces; 0: only --margin.")
@click.option("--min-volume", type=float, default=None,
              help=f"Smallest region kept (m^3) [default: {DEFAULT_MIN_VOXELS} voxels, a 3x3x3 block].")
@force_option
@click.option("--json", "as_json", is_flag=True, help="Print changes.json to stdout.")
@click.option("--quiet", is_flag=True, help="No progress output.")
def command(before: Path, after: Path, outdir: Path, pois_path, match_radius, margin, noise_sigmas, min_volume, force,
            as_json, quiet) -> None:
    """Compare BEFORE and AFTER (volume.npz or ternary.npz from `kinfu fuse`, same world frame and voxel size):
    removed = occupied before and empty after, added = the reverse. Voxels unknown in either are ignored (and
    counted); a change must be --margin voxels away from every surface of the other volume (pose noise), and
    farther where the depth noise at its distance from the cameras (trajectory.tum beside the volumes) is larger;
    26-connected changed voxels form a region, regions smaller than --min-volume are dropped. Grids with
    different origins or shapes are compared on their common box (nearest voxel).

    Writes OUTDIR/changes.json (per region: id, kind, centroid, box_min/box_max, volume_m3, voxels, ply; counts,
    overlap, warnings), OUTDIR/regions/<id>.ply (the region's voxel centres) and OUTDIR/changes.ply (removed
    red, added green). With --pois, each POI within --match-radius of a region's nearest voxel is a true
    positive; regions with no POI near are false negatives; precision, recall and F1 go to changes.json "pois"
    (null when undefined: no POI scored, no region). A POI near no region is not scored (counted and warned)
    when it lies outside the common box, or where under 10 % of the space within --match-radius is known in
    both volumes (one never observed it); one farther than --match-radius outside both grids is an error.

    \b
    Example:
      kinfu diff out/scan/volume.npz out/fuse/volume.npz -o out/diff --pois out/pois.json
      kinfu diff before/ternary.npz after/ternary.npz --min-volume 5e-5 --json --quiet
    """
    before, after = volume_file(before), volume_file(after)
    claim_outputs({"outdir": outdir}, [before, after, pois_path], force)
    params = change_params(click.get_current_context().params)
    check_inapplicable(click.get_current_context(), INAPPLICABLE)  # after the values' own errors
    pois = read_pois(pois_path) if pois_path is not None else None  # a bad POI file fails before any work
    result = None
    for step in progress(["diff", "write"], total=2, desc="diff", quiet=quiet):
        if step == "diff":
            result = diff_volumes(before, after, params)
            if pois is not None:
                score_pois_in_comparison(result, pois, radius=match_radius, source=str(pois_path))
                result.warnings += poi_frame_warnings(pois_path, result.frame, "--pois")
        else:
            result.warnings = option_warnings_first(result.warnings)
            with atomic_dir(outdir, own=CHANGE_ENTRIES, force=force) as tmp:  # the folder appears whole or not at all
                write_change_outputs(result, tmp)
    doc = result.to_json()
    print_warnings(doc)
    if as_json:
        click.echo(json.dumps(doc, indent=2, default=float))
    elif not quiet:
        for line in _lines(doc, outdir):
            click.echo(line)
