"""`kinfu nbv`: rank candidate views around each POI by information gain (ray casting the ternary map)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import click

from kinfu_cli.commands._options import (Inapplicable, OutputPath, check_inapplicable, claim_outputs, force_option,
                                         volume_file)
from kinfu_cli.commands._output import emit
from kinfu_cli.commands._up import parse_up
from kinfu_cli.core.camera import CameraModel
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.pois import DEFAULT_RADIUS, poi_frame_warnings
from kinfu_cli.fusion.volume import volume_intrinsics
from kinfu_cli.nbv.gains import gain_names
from kinfu_cli.nbv.sensor import camera_from_options, camera_source, preset_warning
from kinfu_cli.nbv.viewpoints import PAPER_SPHERE, SphereSpec, read_candidates
from kinfu_cli.nbv.workflow import NbvOptions, rank_object_views, rank_poi_views
from kinfu_cli.report.nbv_plot import plot_nbv


def _table_z_option(value: str):
    v = value.strip().lower()
    if v in ("auto", "none"):
        return v
    try:
        z = float(v)
    except ValueError:
        z = math.nan
    if not math.isfinite(z) or abs(z) > 1e4:  # nan / inf would reject every view, or none, silently
        raise ConfigError(f"--table-z: expected auto, none or a height in metres, got {value!r}")
    return z


def _up_option(value: str) -> tuple[float, float, float] | None:
    up_dir = parse_up(value, ("auto",))
    return None if isinstance(up_dir, str) else tuple(float(v) for v in up_dir)


# options of the POI mode's viewing sphere and ranking that --mode objects has no use for: its candidates are 5
# directions x 8 rolls at 0.8 m around each contour point (nbv.objects), no sphere around a POI
# (a --candidates or --pois file given there would be read by nobody: a damaged or wrong one passed silently)
POI_MODE_ONLY = ("pois", "candidates", "clear", "plot", "radius", "lon-step", "lat-min", "lat-max", "lat-step",
                 "roll-step", "poi-radius", "clearance", "optimistic", "exact-rolls")
#: the viewing sphere's options, which --candidates replaces
SPHERE_OPTIONS = ("radius", "lon-step", "lat-min", "lat-max", "lat-step", "roll-step")
# options given where they do nothing (commands._options.check_inapplicable)
INAPPLICABLE = (
    Inapplicable(POI_MODE_ONLY, lambda p: "with --mode objects" if p["mode"] == "objects" else None,
                 "to --mode poi (--mode objects places its own views: 5 directions x 8 rolls at 0.8 m around each "
                 "contour point, no viewing sphere around a POI)", warn=False),
    Inapplicable(SPHERE_OPTIONS, lambda p: "with --candidates" if p["candidates"] is not None else None,
                 "to the viewing sphere, which the --candidates poses replace"),
)


def _camera(p: dict, recorded: dict | None) -> CameraModel:
    """The sensor model from the parsed options; `recorded`: the intrinsics the volume was fused with."""
    return camera_from_options(p["fx"], p["fy"], p["cx"], p["cy"], p["width"], p["height"], p["camera_info"],
                               p["min_range"], p["max_range"], p["vfov_extra"], recorded=recorded,
                               recorded_from=str(p.get("volume") or "the volume"))


def nbv_options(p: dict) -> NbvOptions:
    """The POI planner's options from the command's parsed options (click's parameter dict): the one place that
    turns them into NbvOptions, for the command and for `check_options`."""
    sphere = SphereSpec(radius=p["radius"], lon_step=p["lon_step"], lat_min=p["lat_min"], lat_max=p["lat_max"],
                        lat_step=p["lat_step"], roll_step=p["roll_step"])
    return NbvOptions(gain=p["gain"], clear=p["clear"], top=p["top"], candidates=p["candidates"], sphere=sphere,
                      poi_radius=p["poi_radius"], inc_th=p["inc_th"], table_z=_table_z_option(p["table_z"]),
                      clearance=p["clearance"], share_rolls=not p["exact_rolls"], optimistic=p["optimistic"],
                      up=_up_option(p["up"]))


def check_options(params: dict) -> None:
    """What `kinfu nbv` (POI mode) refuses with these options before it reads the volume and the POIs (kinfu
    batch checks a plan with it): the options, the viewing sphere (or the --candidates file) and the sensor
    model (unless it comes from --camera-info, a recording); ConfigError naming the parameter."""
    opts = nbv_options(params)
    opts.validate()
    if opts.candidates is None:
        opts.sphere.viewpoints((0.0, 0.0, 0.0), up=opts.up)  # the sphere's own range checks
    else:
        read_candidates(opts.candidates)
    if params["camera_info"] is None:
        _camera(params, None)


def summary_lines(doc: dict) -> list[str]:
    """Human-readable summary of a views.json document of the POI mode."""
    lines = []
    for p in doc["pois"]:
        rej = ", ".join(f"{k} {v}" for k, v in p["rejected"].items() if v) or "none"
        state = ("unreachable (no view sees into it)" if p.get("unreachable") else
                 "reconstructed" if p["reconstructed"] else "not reconstructed")
        x, y, z = p["position"]
        judged = p.get("inc_th_gain", doc["gain"])
        on = f" on the {judged} gain" if judged != doc["gain"] else ""
        best = (f"best {doc['gain']} gain {p['best_gain']:.1f} (IncTh {p['inc_th']:.1f}{on}): {state}" if p["valid"]
                else "no valid view to rank")
        lines.append(f"POI {p['id']} at ({x:.3f}, {y:.3f}, {z:.3f}) r={p['radius']:.2f} m: "
                     f"{p['candidates']} candidates, rejected: {rej}; {best}")
        lines.append("  rank      gain   unknown  occupied  empty-exit  position")
        for i, v in enumerate(p["views"][:10]):
            px, py, pz = v["position"]
            lines.append(f"  {i + 1:4d} {v['gain']:9.1f} {v['rays_unknown']:9d} {v['rays_occupied']:9d} "
                         f"{v['rays_empty_exit']:11d}  ({px:.3f}, {py:.3f}, {pz:.3f})")
    return lines


def objects_summary_lines(doc: dict) -> list[str]:
    """Human-readable summary of a views.json document of the objects mode."""
    if doc["pose"] is None:
        if doc.get("empty_reason"):
            return [f"no view to plan: {doc['empty_reason']}"]
        return [f"no view scores above {doc['score_threshold']} on any segment ({len(doc['attempts'])} tried): "
                "the objects are considered reconstructed"]
    r = doc["region"]
    c = r["center"]
    lines = [f"segment {doc['segment_id']} (region centre ({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}), r={r['radius']:.2f} m):"
             f" best {doc['gain']} gain {doc['score']:.1f}; {doc['candidates_evaluated']} of "
             f"{doc['candidates_total']} candidates ray-cast",
             "  rank      gain  position"]
    for i, v in enumerate(doc["views"][:10]):
        px, py, pz = v["position"]
        lines.append(f"  {i + 1:4d} {v['gain']:9.1f}  ({px:.3f}, {py:.3f}, {pz:.3f})")
    return lines


@click.command("nbv", short_help="Rank next-best views around each POI by information gain.")
@click.argument("volume", type=click.Path(path_type=Path))
@click.option("--pois", "pois_path", default=None, type=click.Path(path_type=Path),
              help="pois.json from `kinfu poi` (needed with --mode poi).")
@click.option("--mode", default="poi", show_default=True, type=click.Choice(["poi", "objects"]),
              help="poi: viewing sphere around each POI (RAS 2016); objects: object-driven views at the "
                   "contours of the most salient segment (thesis Alg. 4).")
@click.option("--clear", is_flag=True, help="First set every POI sphere to unknown (the paper's ForgetAround).")
@click.option("--gain", default="unknown", show_default=True,
              type=click.Choice(gain_names()), help="Gain function.")
@click.option("--top", default=10, show_default=True, type=click.IntRange(min=0),
              help="Views listed per POI (0 = all valid views).")
@click.option("-o", "--output", type=OutputPath(kind="json"), default=None, help="Write views.json here.")
@click.option("--plot", type=OutputPath(kind="image"), default=None,
              help="PNG: volume slices with each POI sphere and its top views as arrows.")
@click.option("--viz", type=OutputPath(dir_okay=False, kind="viewer"), default=None,
              help="Also write a viewer file: an MCAP of Foxglove messages (occupied voxels and each ranked view as a camera frustum); open it in Foxglove.")
@click.option("--candidates", type=click.Path(path_type=Path), default=None,
              help="JSON list of 4x4 camera-to-world poses to score instead of the viewing sphere.")
@click.option("--radius", default=PAPER_SPHERE.radius, show_default=True, type=float,
              help="Viewing sphere radius d (m).")
@click.option("--lon-step", default=PAPER_SPHERE.lon_step, show_default=True, type=float,
              help="Longitude step (deg).")
@click.option("--lat-min", default=PAPER_SPHERE.lat_min, show_default=True, type=float,
              help="Lowest latitude (deg).")
@click.option("--lat-max", default=PAPER_SPHERE.lat_max, show_default=True, type=float,
              help="Highest latitude (deg).")
@click.option("--lat-step", default=PAPER_SPHERE.lat_step, show_default=True, type=float,
              help="Latitude step (deg).")
@click.option("--roll-step", default=PAPER_SPHERE.roll_step, show_default=True, type=float,
              help="Roll step about the optical axis (deg).")
@click.option("--poi-radius", default=None, type=float,
              help=f"Radius of S(POI) in m [default: each POI's radius, {DEFAULT_RADIUS}].")
@click.option("--fx", type=float, default=None, help="Focal length x (px).")
@click.option("--fy", type=float, default=None, help="Focal length y (px).")
@click.option("--cx", type=float, default=None, help="Principal point x (px).")
@click.option("--cy", type=float, default=None, help="Principal point y (px).")
@click.option("--width", type=int, default=None, help="Image width (px) [640].")
@click.option("--height", type=int, default=None, help="Image height (px) [480].")
@click.option("--camera-info", type=click.Path(path_type=Path), default=None,
              help="Recording whose sensor_msgs/CameraInfo gives the intrinsics [default: those the volume was "
                   "fused with; Kinect v1 525/319.5/239.5 when it has none].")
@click.option("--min-range", default=0.5, show_default=True, type=float, help="Sensor minimum range (m).")
@click.option("--max-range", default=4.0, show_default=True, type=float, help="Sensor maximum range (m).")
@click.option("--vfov-extra", default=5.0, show_default=True, type=float,
              help="Extra vertical FOV (deg, each side) modelling the +-5 deg oscillation.")
@click.option("--inc-th", type=float, default=None,
              help="IncTh: a POI is reconstructed when its best gain is below this [default: 1% of the "
                   "pixels that see S(POI)].")
@click.option("--table-z", default="auto", show_default=True,
              help="Reject sensor positions below this height along up: auto (table top found in the volume), "
                   "none, or metres.")
@click.option("--up", default="auto", show_default=True, metavar="X,Y,Z|auto",
              help="The world's up direction (viewing sphere, table): auto = the volume's (z when it has none).")
@click.option("--clearance", default=0.0, show_default=True, type=float,
              help="Reject sensor positions within this distance (m) of occupied/unknown voxels; with a clearance, "
                   "space outside the volume counts as unknown (never observed).")
@click.option("--optimistic", is_flag=True,
              help="Unknown voxels outside S(POI) do not stop rays (the paper: the first unknown voxel stops a ray).")
@click.option("--exact-rolls", is_flag=True, help="Cast every view's own rays (no sharing between rolls; slower).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="Print the result JSON on stdout.")
@force_option
def command(volume, pois_path, mode, clear, gain, top, output, plot, candidates, radius, lon_step, lat_min, lat_max,
            lat_step, roll_step, poi_radius, fx, fy, cx, cy, width, height, camera_info, min_range, max_range,
            vfov_extra, inc_th, table_z, up, clearance, optimistic, exact_rolls, quiet, as_json, force, viz=None):
    """Rank candidate views around each POI by the information gain inside S(POI).

    Ray casts each candidate (the paper's viewing sphere: d = 0.8 m, longitude 30 deg, latitude
    0-90 deg by 10, roll 45 deg = 960 poses, or --candidates) through the ternary volume; a ray stops
    at the first occupied or unknown voxel. Sensor positions inside occupied/unknown space or below
    the table are rejected with a reason. Output per POI: views sorted by gain with pose (4x4
    camera-to-world), position, quaternion (x, y, z, w), gain and ray counts; IncTh says whether the
    POI is considered reconstructed. With --mode objects no POIs are needed: the views come from
    the contours of the most salient segment (thesis Alg. 4; --inc-th is its score threshold).

    \b
    Example:
      kinfu nbv out/fuse/volume.npz --pois out/pois.json --clear -o out/views.json --plot out/views.png
      kinfu nbv volume.npz --pois pois.json --gain entropy --top 5 --json
      kinfu nbv volume.npz --mode objects -o views.json
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    volume = volume_file(volume)
    claim_outputs({"output": output, "plot": plot, "viz": viz}, [volume, pois_path, candidates, camera_info], force,
                  recordings=[camera_info])
    t0 = time.perf_counter()
    recorded = volume_intrinsics(volume) if Path(volume).is_file() else None
    params = click.get_current_context().params
    cam = _camera(params, recorded)
    source = camera_source(fx, fy, cx, cy, camera_info, recorded)
    camera_warnings = [preset_warning()] if source == "kinect_v1 preset" else []
    up_dir = _up_option(up)
    if mode == "objects":
        planned = rank_object_views(volume, cam, gain=gain, table_z=_table_z_option(table_z),
                                    score_threshold=0.0 if inc_th is None else inc_th, top=top, up=up_dir)
        doc = planned.to_json()
        doc["camera_source"] = source
        doc["warnings"] = camera_warnings + doc["warnings"]
        doc["seconds"] = round(time.perf_counter() - t0, 3)
        if viz is not None:
            from kinfu_cli.report.viewer import write_viewer  # protobuf and segmentation: only for --viz

            write_viewer(viz, views=planned, grid=planned.grid)
        emit(doc, output, as_json, objects_summary_lines, quiet)
        return
    if pois_path is None:
        raise ConfigError("--pois: required with --mode poi (a pois.json from `kinfu poi`)")
    ranked = rank_poi_views(volume, pois_path, cam, nbv_options(params), quiet=quiet)
    doc = ranked.to_json()
    doc["camera_source"] = source
    doc["warnings"] = camera_warnings + poi_frame_warnings(pois_path, ranked.grid.frame, "--pois") + doc["warnings"]
    if plot is not None:
        plot_nbv(plot, ranked.grid, ranked.rankings, top=min(top or 5, 5), up=ranked.up)
        doc["plot"] = str(plot)
    if viz is not None:
        from kinfu_cli.report.viewer import write_viewer  # protobuf and segmentation: only for --viz

        write_viewer(viz, views=ranked, grid=ranked.grid)
    doc["seconds"] = round(time.perf_counter() - t0, 3)
    emit(doc, output, as_json, summary_lines, quiet)
