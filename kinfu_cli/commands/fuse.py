"""`kinfu fuse`: KinectFusion TSDF volume with unknown / empty / occupied per voxel from a recording."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from kinfu_cli.commands._options import (Inapplicable, OutputPath, bag_folder, check_inapplicable, claim_outputs,
                                         comma_numbers, force_option, given_options)
from kinfu_cli.commands._output import print_warnings, with_option_warnings
from kinfu_cli.commands._roles import role_kwargs, role_options
from kinfu_cli.commands._up import parse_up
from kinfu_cli.core.atomic import atomic_dir, write_json
from kinfu_cli.core.camera import parse_intrinsics
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.fusion.outputs import OUTPUTS, fusion_report, write_fusion_outputs
from kinfu_cli.fusion.pipeline import fuse_recording
from kinfu_cli.fusion.tracking import PHOTO_WEIGHT
from kinfu_cli.report.volume_plot import plot_slices

# how report.json names the arguments that placed the grid or cleared spheres: by their options
ARGUMENT_FLAGS = {"init": "--init", "origin": "--origin", "clear_spheres": "--clear-sphere",
                  "clear_pois": "--clear-pois", "up": "--up", "voxel_size": "--voxel-size", "size": "--size",
                  "resolution": "--resolution"}


def _share(value: str) -> float:
    """--max-lost: a share 0..1, or a percentage ("10%")."""
    text = value.strip()
    try:
        share = float(text[:-1]) / 100 if text.endswith("%") else float(text)
    except ValueError:
        raise ConfigError(f"--max-lost: expected a share like 0.1 or 10%, got {value!r}") from None
    if not 0 <= share <= 1:
        raise ConfigError(f"--max-lost: expected a share in [0, 1] (0-100%), got {value!r}")
    return share


def _floats(value: str, name: str, n: tuple[int, ...]) -> tuple[float, ...]:
    v = comma_numbers(value, name) or []  # an empty item ('1,,2') is the list options' error
    if len(v) not in n:  # nan / inf (None above): int() of them was a traceback
        want = " or ".join(str(k) for k in n)
        raise ConfigError(f"{name}: expected {want} comma-separated finite numbers, got {value!r}")
    return tuple(v)


# options given in a mode where they do nothing (commands._options.check_inapplicable): warnings, as a script or a
# batch plan sets them for recordings fused in either pose mode, and --max-memory is the machine's budget
INAPPLICABLE = (
    Inapplicable(("max-lost", "icp", "photometric-weight"), lambda p: f"with --pose {p['pose']}"
                 if p["pose"] in ("forced", "topic") else None, "to --pose icp or hint"),
    Inapplicable(("photometric-weight",), lambda p: "with --icp open3d" if p["icp"] == "open3d" else None,
                 "to --icp projective"),
    Inapplicable(("max-memory",), lambda p: "with --init" if p["init"] else (
        f"with --size {p['size']}" if p["size"].strip().lower() != "auto" else None), "to --size auto"),
    # --color mode with --no-color is a contradiction fusion refuses itself (ConfigError naming --color)
    Inapplicable(("color",), lambda p: "with --no-color" if p["no_color"] and p["color_mode"] != "mode" else None,
                 "to fusion with colour"),
)


def unused_tracking_options(ctx: click.Context, pose_mode: str) -> list[str]:
    """The warning for --max-lost / --icp given without --pose when the recording decided on poses without tracking
    (its TF has the camera: forced; a pose topic): known only once the recording is read, so it goes into
    report.json's warnings (an explicit --pose forced|topic is warned about before any work, INAPPLICABLE)."""
    given = given_options(ctx, ("max-lost", "icp", "photometric-weight")) if ctx.params["pose"] is None else []
    if not given or pose_mode not in ("forced", "topic"):
        return []
    one = len(given) == 1
    return [f"{', '.join(given)} {'has' if one else 'have'} no effect: the recording gave the camera poses "
            f"(--pose {pose_mode}, chosen from it), no frame was tracked (ignored)"]


def fuse_arguments(params: dict) -> dict:
    """fuse_recording's keywords from the command's parsed options (click's parameter dict): the one place that
    turns fuse's options into library arguments, for the command and for `check_options`."""
    p = dict(params)
    voxel_size, resolution, size, origin = p["voxel_size"], p["resolution"], p["size"], p["origin"]
    if voxel_size is not None and resolution is not None:
        raise ConfigError("--voxel-size and --resolution: give one of them, not both")
    res = None
    if resolution is not None:
        r = _floats(resolution, "--resolution", (1, 3))
        if any(x != int(x) or x < 1 for x in r):
            raise ConfigError(f"--resolution: expected positive integers, got {resolution!r}")
        res = int(r[0]) if len(r) == 1 else tuple(int(x) for x in r)
    if size.strip().lower() == "auto":
        grid_size = "auto"
    else:
        sz = _floats(size, "--size", (1, 3))
        grid_size = sz[0] if len(sz) == 1 else sz
    init, clear_pois = p["init"], p["clear_pois"]
    return dict(
        size=grid_size, resolution=res, voxel_size=voxel_size,
        origin=_floats(origin, "--origin", (3,)) if origin else None, truncation=p["truncation"],
        max_weight=p["max_weight"], min_depth=p["min_depth"], max_depth=p["max_depth"], color=not p["no_color"],
        pose=p["pose"], pose_topic=p["pose_topic"], init=str(init) if init else None,
        clear_spheres=[_floats(s, "--clear-sphere", (4,)) for s in p["clear_spheres"]],
        clear_pois=str(clear_pois) if clear_pois else None, start_s=p["start_s"], end_s=p["end_s"],
        every=p["every"], tolerance_s=p["tolerance_s"], fill_gaps=p["fill_gaps"], bilateral=p["bilateral"],
        shadow_filter=p["shadow_filter"], roles=role_kwargs(p), quiet=p["quiet"], argument_names=ARGUMENT_FLAGS,
        max_lost=_share(p["max_lost"]), max_memory=p["max_memory"], color_mode=p["color_mode"], icp=p["icp"],
        photometric_weight=p["photometric_weight"],
        up=None if isinstance(up_dir := parse_up(p["up"], ("auto",)), str) else up_dir)


def check_options(params: dict) -> None:
    """What `kinfu fuse` refuses with these options before it opens the recording (kinfu batch checks a plan
    with it); ConfigError naming the parameter."""
    fuse_recording(None, **fuse_arguments(params), check_only=True)
    parse_intrinsics(params["intrinsics"])  # else parsed when the recording's roles are detected


@click.command("fuse", short_help="Fuse depth frames into a ternary TSDF volume, mesh and cloud.")
@click.argument("recording", type=click.Path(path_type=Path))
@click.option("-o", "--output", "outdir", type=OutputPath(file_okay=False, kind="folder"), required=True,
              help="Output folder (mesh.ply, cloud.ply, volume.npz, ternary.npz, report.json).")
@click.option("--voxel-size", type=float, default=None,
              help="Voxel edge in metres (instead of --resolution) [size/512; with --size auto 3/512 m, coarser "
                   "when the grid would exceed --max-memory].")
@click.option("--resolution", default=None,
              help="Voxels per axis: N or nx,ny,nz [512 with a --size; with --size auto over the observed box].")
@click.option("--size", default="auto", show_default=True,
              help="Grid edge in metres: S or sx,sy,sz, or auto: a box around everything the selected frames "
                   "observe (a quick first pass over their poses and depth), plus a margin.")
@click.option("--max-memory", type=float, default=None, metavar="GIB",
              help="Memory budget of --size auto (worst case of the grid) in GiB [half the available memory, at "
                   "most 2]; above it the default voxel grows, a given --voxel-size crops the box.")
@click.option("--origin", default=None, help="World position x,y,z of the grid's minimum corner [with --size "
                                             "auto the observed box's; else centred on what the first frames "
                                             "observe].")
@click.option("--truncation", type=float, default=None,
              help="TSDF truncation M_v (m) [default: 0.03, or 0.75 voxel for voxels over 4 cm].")
@click.option("--max-weight", type=int, default=128, show_default=True, help="Weight cap M_w (1..255).")
@click.option("--min-depth", type=float, default=0.3, show_default=True, help="Ignore closer readings (m).")
@click.option("--max-depth", type=float, default=4.0, show_default=True, help="Ignore farther readings (m).")
@click.option("--pose", type=click.Choice(["forced", "icp", "hint", "topic"]), default=None,
              help="Camera poses: forced (TF, no tracking), icp (frame-to-model), hint (ICP from TF; a frame ICP "
                   "cannot refine is fused at its TF pose), topic (--pose-topic) [forced when TF has the camera "
                   "frame, else icp].")
@click.option("--pose-topic", default=None, metavar="TOPIC", help="PoseStamped/Odometry topic for --pose topic.")
@click.option("--max-lost", default="10%", show_default=True, metavar="SHARE",
              help="With --pose icp/hint: fail when tracking loses more than this share of the tracked frames "
                   "(0.1 or 10%). Lost frames (ICP fitness < 0.3, depth agreeing with the model on < 75 % of "
                   "the shared pixels, a flat view, or a jump faster than 3 m/s or 600 deg/s; re-localisation "
                   "tried first) are never fused. hint loses only frames ICP puts over 10 cm / 10 deg from TF.")
@click.option("--icp", type=click.Choice(["projective", "open3d"]), default="projective", show_default=True,
              help="With --pose icp/hint: the tracker's ICP: projective (KinFu's projective point-to-plane on a "
                   "depth pyramid, numba, real time) or open3d (point-to-plane on clouds, ~20x slower; reference).")
@click.option("--photometric-weight", type=float, default=PHOTO_WEIGHT, show_default=True, metavar="W",
              help="With --pose icp/hint and --icp projective: the weight of the colour term (each frame's "
                   "intensities against the last fused frame's) beside the point-to-plane one; it holds the pose "
                   "where depth alone slides (a wall and the floor). 0: depth only. Needs colour.")
@click.option("--init", "init", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Continue fusing into this volume.npz (its grid wins over the grid options).")
@click.option("--clear-sphere", "clear_spheres", multiple=True, metavar="X,Y,Z,R",
              help="Forget a sphere (set unknown); repeatable. With --init before fusing, else after.")
@click.option("--clear-pois", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Forget a sphere around each POI of this pois.json (its radius, default 0.2 m).")
@click.option("--start", "start_s", type=float, default=None, help="Start time, seconds from the recording start.")
@click.option("--end", "end_s", type=float, default=None, help="End time, seconds from the recording start.")
@click.option("--every", type=int, default=1, show_default=True, help="Use every N-th depth frame.")
@click.option("--tolerance", "tolerance_s", type=float, default=0.05, show_default=True,
              help="Largest depth/colour stamp difference, and how far a pose may be extrapolated (s).")
@click.option("--fill-gaps", type=click.IntRange(min=0), default=2, show_default=True, metavar="N",
              help="Fill invalid runs of up to N pixels along a row or column between two readings that agree "
                   "within 3 % (lines of no reading some sensors leave); 0 turns it off.")
@click.option("--bilateral", is_flag=True, help="Bilateral-filter the depth images first.")
@click.option("--shadow-filter", is_flag=True, help="Remove Kinect V2 shadow and veil pixels (thesis 3.1.3).")
@click.option("--up", default="auto", show_default=True, metavar="X,Y,Z|auto",
              help="Direction against gravity in the world frame. auto: z for a REP-103 TF frame (world, map, "
                   "odom, ...) unless the recording says otherwise, else the largest plane below the cameras "
                   "(report.json: up, up_source).")
@click.option("--no-color", is_flag=True, help="Do not keep colour per voxel.")
@click.option("--color", "color_mode", type=click.Choice(["mean", "mode"]), default=None,
              help="Voxel colour: mean (running mean) or mode (a few colour hypotheses per voxel, the most seen "
                   "wins: sharp colour edges under auto-gain and colour/depth misregistration; thesis ch. 4) "
                   "[mean; with --init the volume's].")
@click.option("--plot", is_flag=True, help="Also write PNG slices of the ternary volume.")
@click.option("--viz", type=OutputPath(dir_okay=False, kind="viewer"), default=None,
              help="Also write a viewer file: an MCAP of Foxglove messages (mesh, cloud, camera trajectory and intrinsics); open it in Foxglove.")
@force_option
@click.option("--json", "as_json", is_flag=True, help="Print report.json to stdout.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@role_options
def command(recording: Path, outdir: Path, voxel_size, resolution, size, origin, truncation, max_weight, min_depth,
            max_depth, pose, pose_topic, init, clear_spheres, clear_pois, start_s, end_s, every, tolerance_s,
            fill_gaps, bilateral, shadow_filter, up, no_color, color_mode, plot, as_json, quiet, force, max_memory,
            max_lost, icp, viz=None, **kwargs) -> None:
    """Fuse the depth frames of RECORDING (MCAP, ROS 1 .bag, ROS 2 bag folder) into a KinectFusion TSDF
    volume that keeps unknown / empty / occupied per voxel (Monica et al. 2016, eqs. 1-3): free space in
    front of surfaces becomes known-empty, interiors stay unknown. Writes OUTDIR/mesh.ply (coloured),
    cloud.ply, volume.npz (continue with --init), ternary.npz (int8 [x,y,z]: 1 occupied, 0 unknown,
    -1 empty; origin; voxel_size; up) and report.json (frames used/dropped, poses, up direction, depth
    intrinsics, tracking, timing, counts, bounding box, grid sizing, warnings). segment and nbv use the up
    direction and nbv the intrinsics stored in volume.npz.

    The grid is sized to the scene by default (--size auto) and the note line says what was chosen;
    occupied voxels on a face of the grid give a warning (the scene goes on beyond it). With --pose icp or
    hint, frames whose tracking is lost are reported (report.json tracking.lost, per-frame fitness, rmse,
    agreement) and not fused; more than --max-lost of them fail the run (exit 2). In hint mode a frame ICP
    cannot refine (new territory, too little overlap, a flat view) is fused at its TF pose, as forced would
    (tracking.tf_fallback_frames); only a pose ICP finds far from TF is lost. With recorded poses the
    report gives the tracked trajectory's error against them (tracking.ate_vs_given_m).

    \b
    Example:
      kinfu fuse sample_data/tabletop/recording.mcap -o out/fuse --plot
      kinfu fuse rec.bag -o out/fuse --voxel-size 0.01 --size 2,2,1 --pose icp --every 2
      kinfu fuse room.mcap -o out/room --voxel-size 0.01 --max-memory 4
      kinfu fuse rec.mcap -o out/icp --pose icp --every 5 --max-lost 5%
      kinfu fuse rec2.mcap -o out/fuse2 --init out/fuse/volume.npz --clear-pois out/poi/pois.json
    """
    claim_outputs({"outdir": outdir, "viz": viz}, [recording, bag_folder(recording), init, clear_pois], force,
                  recordings=[recording])
    arguments = fuse_arguments(click.get_current_context().params)  # a malformed value: its error, no warning first
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    result = fuse_recording(recording, **arguments)
    if not quiet:
        for note in result.notes:
            click.echo(f"kinfu: note: {note}", err=True)
    t0 = time.perf_counter()
    with atomic_dir(outdir, own=(*OUTPUTS, "slices_*.png"), force=force) as tmp:  # one transaction: report.json written last
        write_fusion_outputs(result, tmp)
        plots = [p.name for p in plot_slices(result.grid, tmp)] if plot else []
        result.add_time("write", time.perf_counter() - t0)
        report = fusion_report(result, extra_outputs=plots)
        report["warnings"] = [*unused_tracking_options(click.get_current_context(), result.pose_mode),
                              *report["warnings"]]
        with_option_warnings(report)
        write_json(tmp / "report.json", report)
    if viz is not None:
        from kinfu_cli.report.viewer import write_viewer  # protobuf and segmentation: only for --viz

        write_viewer(viz, fusion=result)
    print_warnings(report)
    if as_json:
        click.echo(json.dumps(report, indent=2, default=str))
    elif not quiet:
        c = report["counts"]
        f = report["frames"]
        t = report["tracking"]
        lost = f", {t['lost']} lost by tracking" if t and t["lost"] else ""
        lost += f", {t['tf_fallback']} at their TF pose (ICP failed)" if t and t["tf_fallback"] else ""
        ate = t and t["ate_vs_given_m"]
        ate = f", {ate['rmse'] * 100:.2f} cm RMS from the recorded poses" if ate else ""
        click.echo(f"fused {f['used']} frames ({f['dropped_total']} dropped{lost}) with poses {report['pose_mode']}"
                   f"{ate}: {c['occupied']} occupied, {c['empty']} empty, {c['unknown']} unknown voxels -> {outdir}")
