"""`kinfu segment`: segments of the fused surface, their saliency (thesis eq. 3.12) and superquadrics.

Grasp planning, plots and the viewer are imported inside the functions that use them: the default run
(issue 12: <= 2 s end to end) does not pay for scipy's rotations, matplotlib or protobuf.
"""

from __future__ import annotations

import json
from dataclasses import fields, replace
from pathlib import Path

import click
from click.core import ParameterSource

from kinfu_cli.commands._options import (Inapplicable, OutputPath, check_inapplicable, claim_outputs, comma_numbers,
                                         force_option, volume_file)
from kinfu_cli.commands._output import print_warnings, with_option_warnings
from kinfu_cli.commands._up import parse_up
from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.progress import progress
from kinfu_cli.segmentation.outputs import SEGMENT_ENTRIES, write_segment_outputs
from kinfu_cli.segmentation.pipeline import SegmentOptions, SegmentResult, segment_volume
from kinfu_cli.segmentation.segments import COLOR_DISTANCES, SegmentationParams


def _pair(value: str, name: str) -> tuple[float, float]:
    v = comma_numbers(value, name) or []  # an empty item ('0.1,') is the list options' error
    if len(v) != 2:
        raise ConfigError(f"{name}: expected two numbers 'lo,hi', got {value!r}")
    return v[0], v[1]


_MULTI_SQ = ("msq-trigger", "msq-height", "msq-mu", "msq-cut")
# options given where they do nothing (commands._options.check_inapplicable): the first that applies is the error
INAPPLICABLE = (
    Inapplicable(("grasp-hand", "grasp-cone", "grasp-starts"), lambda p: None if p["grasp"] else "without --grasp",
                 message="{flags}: needs --grasp (no grasps are planned without it)", warn=False),
    Inapplicable(("t-lccp", "concave-cut", "concavity-tolerance", "sanity-angle", "seed-resolution",
                  "spatial-importance"), lambda p: "with --method flood-fill" if p["method"] == "flood-fill" else None,
                 "to --method lccp (flood fill joins points, without supervoxels or LCCP's edge tests)"),
    Inapplicable(("t-ff",), lambda p: "with --method lccp" if p["method"] == "lccp" else None,
                 "to --method flood-fill"),
    Inapplicable(("color-importance", "t-lccp", "color-distance", "plane-color-margin"),
                 lambda p: "with --no-color" if p["no_color"] else None, "to a segmentation with colour"),
    Inapplicable(("color-distance",), lambda p: "with --method lccp without --t-lccp"
                 if p["method"] == "lccp" and p["t_lccp"] is None else None,
                 "to the colour tests --t-lccp and --t-ff (--method flood-fill)"),
    Inapplicable(("sq-max-points", "sq-exponent-bounds", "sq-cost", "shape-prior", "multi-sq", *_MULTI_SQ),
                 lambda p: "with --no-superquadrics" if p["no_superquadrics"] else None, "to the superquadric fits"),
    Inapplicable(_MULTI_SQ, lambda p: None if p["multi_sq"] else "without --multi-sq", "with --multi-sq"),
    Inapplicable(("up-tolerance",), lambda p: "with --up none" if p["up"].strip().lower() == "none" else None,
                 "to a support plane searched along an up direction (--up auto or x,y,z)"),
)


def _up(value: str) -> tuple[float, float, float] | str | None:
    v = parse_up(value, ("auto", "none"))
    if isinstance(v, str):
        return None if v == "none" else v
    return tuple(float(x) for x in v)  # type: ignore[return-value]


def _grasp_options(hand: str, cones: tuple[str, ...], starts: int, no_superquadrics: bool):
    """--grasp's options (a GraspOptions), checked before any work (cone presets are re-made on the support
    plane found)."""
    from kinfu_cli.grasp.constraints import parse_cone
    from kinfu_cli.grasp.plan import GraspOptions

    if no_superquadrics:
        raise ConfigError("--grasp needs the superquadrics: drop --no-superquadrics")
    try:
        opts = GraspOptions(hand=hand, cones=[parse_cone(c, (0.0, 0.0, 1.0)) for c in cones], n_starts=starts)
        opts.validate()
    except ConfigError as exc:  # name the segment command's flags, not kinfu grasp's
        flag = {"cones": "--grasp-cone", "n_starts": "--grasp-starts"}.get(exc.parameter, "--grasp")
        raise ConfigError(f"{flag}: {exc.detail}") from None
    return opts


def _grasps(segments: dict, options, cones: tuple[str, ...]) -> dict:
    """grasps.json for the segments just found; no object to grasp gives an empty list and a warning."""
    from kinfu_cli.grasp.constraints import parse_cone
    from kinfu_cli.grasp.plan import GraspError, plan_grasps

    plane = segments.get("support_plane")
    up = plane[:3] if plane is not None else (0.0, 0.0, 1.0)
    options = replace(options, cones=[parse_cone(c, up) for c in cones])
    try:
        out = plan_grasps(segments, options).to_json()
    except GraspError as exc:
        return {"source": "segments.json", "grasps": [], "warnings": [f"no grasps: {exc}"]}
    out["source"] = "segments.json"
    return out


def segment_options(p: dict, explicit: tuple[str, ...] = ()):
    """(SegmentOptions, GraspOptions or None) from the command's parsed options (click's parameter dict): the one
    place that turns segment's options into library options, for the command and for `check_options`. explicit:
    the parameters given on the command line (kept, never scaled to a coarse volume's voxel)."""
    grasp_options = (_grasp_options(p["grasp_hand"], p["grasp_cones"], p["grasp_starts"], p["no_superquadrics"])
                     if p["grasp"] else None)
    params = SegmentationParams(seed_resolution=p["seed_resolution"], spatial_importance=p["spatial_importance"],
                                normal_importance=p["normal_importance"], adjacency_radius=p["adjacency_radius"],
                                method=p["method"], color_importance=p["color_importance"], t_lccp=p["t_lccp"],
                                t_ff=p["t_ff"], color_distance=p["color_distance"],
                                plane_color_margin=p["plane_color_margin"],
                                cut_concave_fraction=p["concave_cut"] or None,
                                concavity_tolerance_deg=p["concavity_tolerance"], sanity_angle_deg=p["sanity_angle"],
                                min_segment_points=p["min_segment_points"], fragment_points=p["fragment_points"],
                                plane_distance=p["plane_distance"], up=_up(p["up"]),
                                up_tolerance_deg=p["up_tolerance"], background_margin=p["background_margin"],
                                seed=p["seed"])
    opts = SegmentOptions(resolution=p["resolution"], min_weight=p["min_weight"],
                          isolation_threshold=p["isolation_threshold"], superquadrics=not p["no_superquadrics"],
                          sq_max_points=p["sq_max_points"],
                          sq_exponent_bounds=_pair(p["sq_exponent_bounds"], "--sq-exponent-bounds"),
                          sq_cost=p["sq_cost"], multi_sq=p["multi_sq"], msq_trigger=p["msq_trigger"],
                          msq_height=p["msq_height"], msq_mu=p["msq_mu"], msq_cut=p["msq_cut"],
                          color=not p["no_color"], segmentation=params, shape_prior=p["shape_prior"],
                          explicit=tuple(explicit))
    return opts, grasp_options


def check_options(params: dict) -> None:
    """What `kinfu segment` refuses with these options before it reads the volume (kinfu batch checks a plan
    with it); ConfigError naming the parameter."""
    segment_options(params)[0].validate()


@click.command("segment", short_help="Segments, saliency and superquadrics of a fused volume.")
@click.argument("volume", type=click.Path(path_type=Path))
@click.option("-o", "--output", "outdir", type=OutputPath(file_okay=False, kind="folder"), default=Path("segments"),
              show_default=True, help="Output folder.")
@click.option("--resolution", type=float, default=0.01, show_default=True, help="Surface cloud spacing (m).")
@click.option("--min-weight", type=float, default=1.0, show_default=True, help="TSDF weight of an observed voxel.")
@click.option("--seed-resolution", type=float, default=0.04, show_default=True, help="Supervoxel seed spacing (m).")
@click.option("--spatial-importance", type=float, default=0.1, show_default=True, help="Supervoxel spatial weight.")
@click.option("--normal-importance", type=float, default=1.0, show_default=True, help="Supervoxel normal weight.")
@click.option("--method", type=click.Choice(["lccp", "flood-fill"]), default="lccp", show_default=True,
              help="Supervoxels merged over convex edges (LCCP), or the thesis's Flood Fill baseline.")
@click.option("--color-importance", type=float, default=1.0, show_default=True,
              help="Colour weight (RGB in [0, 1]) in the supervoxels and in the Flood Fill cost.")
@click.option("--no-color", is_flag=True, help="Ignore the volume's colour (segment by shape alone).")
@click.option("--t-lccp", type=float, default=None,
              help="LCCP: cut edges between supervoxels whose mean colours differ more than this (in "
                   "--color-distance: chroma 0..1.41, rgb 0..1.73, angle 0..1.57 rad); default no cut.")
@click.option("--color-distance", type=click.Choice(COLOR_DISTANCES), default="chroma", show_default=True,
              help="Colour distance of --t-lccp and --t-ff: chroma (chromaticity rgb/(r+g+b), blind to shading and "
                   "gain), rgb (the thesis' Euclidean RGB) or angle (between the colour vectors).")
@click.option("--t-ff", type=float, default=0.5, show_default=True,
              help="Flood Fill: neighbours join when colour-importance*|dc| + normal-importance*(1-n1.n2) is below this.")
@click.option("--concave-cut", type=float, default=0.4, show_default=True,
              help="LCCP: cut a segment along the plane of a face at a concave crease when at least this share of "
                   "the point pairs the plane separates are concave (touching boxes); 0 = off (the thesis' LCCP).")
@click.option("--plane-color-margin", type=float, default=0.01, show_default=True,
              help="Object points this close to the support plane (m) join it when their colour is nearer the "
                   "plane's; 0 = off.")
@click.option("--adjacency-radius", type=float, default=0.018, show_default=True,
              help="Points closer than this connect supervoxels (m); not given: 2 voxels on a volume coarser "
                   "than 9 mm.")
@click.option("--concavity-tolerance", type=float, default=40.0, show_default=True,
              help="LCCP: concave edges flatter than this (deg) still merge.")
@click.option("--sanity-angle", type=float, default=60.0, show_default=True, help="LCCP sanity criterion (deg).")
@click.option("--min-segment-points", type=int, default=50, show_default=True,
              help="Smaller segments join a neighbour or are dropped; not given: scaled down with the point density on "
                   "a volume coarser than 1 cm (and --fragment-points alike).")
@click.option("--fragment-points", type=int, default=100, show_default=True,
              help="A segment under this many points whose border runs mostly along one larger object segment "
                   "joins it (a piece of it, not an object); 0 = off.")
@click.option("--plane-distance", type=float, default=0.01, show_default=True, help="Support plane RANSAC inlier distance (m).")
@click.option("--up", default="auto", show_default=True,
              help="Expected support-plane normal: 'x,y,z', 'none' (any plane) or 'auto' (the volume's up, "
                   "stored by kinfu fuse; z when the volume has none).")
@click.option("--up-tolerance", type=float, default=30.0, show_default=True, help="Allowed plane tilt from --up (deg).")
@click.option("--background-margin", type=float, default=0.05, show_default=True,
              help="Segments mostly below the support plane, or past its seen edge by more than this (m), are "
                   "background (kind \"background\" in segments.json: a single view's wall, floor, furniture), "
                   "not objects; 0 = off.")
@click.option("--isolation-threshold", type=float, default=0.02, show_default=True, help="B_th of eq. 3.11 (m).")
@click.option("--no-superquadrics", is_flag=True, help="Skip the superquadric fits.")
@click.option("--sq-max-points", type=int, default=200, show_default=True, help="Points per superquadric fit.")
@click.option("--sq-exponent-bounds", default="0.1,1.9", show_default=True, help="Bounds 'lo,hi' of e1, e2.")
@click.option("--sq-cost", type=click.Choice(["volume", "radial"]), default="volume", show_default=True,
              help="Superquadric residual: thesis eq. 7.2 (volume) or radial distance.")
@click.option("--multi-sq", is_flag=True, help="Split poorly fitted segments into several superquadrics (ch. 8).")
@click.option("--msq-trigger", type=float, default=0.005, show_default=True,
              help="Single-fit RMS residual (m) above which --multi-sq splits.")
@click.option("--msq-height", type=int, default=3, show_default=True, help="Superquadric tree height H.")
@click.option("--msq-mu", type=float, default=0.03, show_default=True, help="Dimension difference mu (m).")
@click.option("--msq-cut", type=click.Choice(["volume", "barycentre"]), default="volume", show_default=True,
              help="Tree root cut: where the two halves' boxes shrink most (ours), or the thesis' barycentre plane.")
@click.option("--shape-prior/--no-shape-prior", default=True, show_default=True,
              help="Classify each segment (box / cylinder / sphere / generic) and fit its superquadric inside the "
                   "class's exponent bounds (thesis eq. 7.11).")
@click.option("--grasp", "grasp", is_flag=True,
              help="Also write grasps.json beside segments.json: kinfu grasp on the segments (its defaults, and "
                   "the --grasp-* options below).")
@click.option("--grasp-hand", type=click.Choice(["right", "left", "both"]), default="both", show_default=True,
              help="With --grasp: as kinfu grasp --hand.")
@click.option("--grasp-cone", "grasp_cones", multiple=True,
              help="With --grasp: as kinfu grasp --cone ('top', 'side' or 'AXIS:dx,dy,dz:deg'; repeatable).")
@click.option("--grasp-starts", type=int, default=4, show_default=True,
              help="With --grasp: optimiser starts per candidate, as kinfu grasp --starts.")
@click.option("--seed", type=int, default=0, show_default=True, help="RANSAC / subsampling seed.")
@click.option("--plot", is_flag=True, help="Also write segments.png and saliency.png.")
@click.option("--viz", type=OutputPath(dir_okay=False, kind="viewer"), default=None,
              help="Also write a viewer file: an MCAP of Foxglove messages (segments, superquadrics and support plane); open it in Foxglove.")
@force_option
@click.option("--json", "as_json", is_flag=True, help="Print segments.json to stdout.")
@click.option("--quiet", is_flag=True, help="No progress output.")
def command(volume: Path, outdir: Path, resolution, min_weight, seed_resolution, spatial_importance,
            normal_importance, method, color_importance, no_color, t_lccp, t_ff, concave_cut, plane_color_margin, adjacency_radius, concavity_tolerance, sanity_angle, min_segment_points,
            fragment_points,
            plane_distance, up, up_tolerance, isolation_threshold, no_superquadrics, sq_max_points,
            sq_exponent_bounds, sq_cost, multi_sq, msq_trigger, msq_height, msq_mu, seed, plot, as_json,
            quiet, force, viz=None, shape_prior=True, grasp=False, grasp_hand="both", grasp_cones=(),
            grasp_starts=4, msq_cut="volume", color_distance="chroma", background_margin=0.05) -> None:
    """Segment the surface of VOLUME (a fusion volume.npz or a ternary.npz): support plane, supervoxels
    merged across convex boundaries (LCCP idea), saliency = isolation x roundness (thesis eq. 3.12) and a
    superquadric per segment (Vezzani ch. 7). Writes OUTDIR/segments.ply (coloured by segment),
    saliency.ply (coloured by saliency) and segments.json (per segment: id, point count, centroid,
    oriented box, isolation, roundness, saliency, superquadric parameters and residual, shape class);
    with --grasp also grasps.json (kinfu grasp's output for these segments).

    \b
    Example:
      kinfu segment out/fuse/volume.npz -o out/segments --plot
      kinfu segment out/fuse/ternary.npz --isolation-threshold 0.01 --json --quiet
      kinfu segment out/fuse/volume.npz -o out/segments --grasp --grasp-hand right --grasp-cone top
    """
    ctx = click.get_current_context()
    check_inapplicable(ctx, INAPPLICABLE)
    volume = volume_file(volume)
    claim_outputs({"outdir": outdir, "viz": viz}, [volume], force)
    given = tuple(f.name for f in fields(SegmentationParams)
                  if ctx.get_parameter_source(f.name) not in (None, ParameterSource.DEFAULT))
    opts, grasp_options = segment_options(ctx.params, given)
    result: SegmentResult | None = None
    doc: dict = {}
    grasps: dict | None = None
    steps = ["segment"] + (["grasp"] if grasp else []) + ["write"]
    for step in progress(steps, total=len(steps), desc="segment", quiet=quiet):
        if step == "segment":
            result = segment_volume(volume, opts)
            doc = with_option_warnings(result.to_json())
        elif step == "grasp":
            grasps = _grasps(doc, grasp_options, grasp_cones)
        else:
            with atomic_dir(outdir, own=SEGMENT_ENTRIES, force=force) as tmp:  # the folder appears whole or not at all
                write_segment_outputs(result, tmp, doc)
                if grasps is not None:
                    write_json(tmp / "grasps.json", grasps)
                if plot:
                    from kinfu_cli.report.segment_plot import plot_segments

                    plot_segments(result, tmp)
    if viz is not None:
        from kinfu_cli.report.viewer import write_viewer

        write_viewer(viz, segments=result)
    print_warnings(doc)
    if grasps is not None:
        print_warnings(grasps)
    if as_json:
        click.echo(json.dumps(doc, indent=2, default=float))
    elif not quiet:
        objs = [s for s in doc["segments"] if s["kind"] == "object"]
        plane = " + support plane" if doc["support_plane"] is not None else ", no support plane"
        n_bg = sum(s["kind"] == "background" for s in doc["segments"])
        plane += f" + {n_bg} background (below the support or beyond it)" if n_bg else ""
        click.echo(f"{len(objs)} segments{plane} from {doc['points']} surface points "
                   f"in {result.timing['total']:.2f} s -> {outdir}/segments.json")
        if grasps is not None:
            ok = sum(g["converged"] for g in grasps["grasps"])
            click.echo(f"grasps: {ok} of {len(grasps['grasps'])} objects -> {outdir}/grasps.json")
        for s in objs[:10]:
            sq = s["superquadric"]
            sq_txt = (f"sq size {[round(v, 3) for v in sq['size']]} e {[round(v, 2) for v in sq['exponents']]} "
                      f"res {sq['residual'] * 1000:.1f} mm" + (f" {s['shape_class']}" if "shape_class" in s else "")
                      ) if sq else "no sq"
            click.echo(f"  #{s['id']:<3} saliency {s['saliency']:.3f} (iso {s['isolation']:.2f} x round "
                       f"{s['roundness']:.2f}) {s['point_count']} pts  {sq_txt}")
