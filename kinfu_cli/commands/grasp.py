"""`kinfu grasp`: a hand pose per segmented object from its superquadric(s) (Vezzani 2019, ch. 7.2, 7.4, 8.2)."""

from __future__ import annotations

import json
from pathlib import Path

import click
from click.core import ParameterSource
import numpy as np

from kinfu_cli.commands._options import (Inapplicable, OutputPath, check_inapplicable, claim_outputs, comma_numbers,
                                         force_option)
from kinfu_cli.commands._output import print_warnings, with_option_warnings
from kinfu_cli.core.atomic import write_json
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.progress import progress
from kinfu_cli.grasp.constraints import PRESET_APERTURE_DEG, Workspace, parse_cone
from kinfu_cli.grasp.hand import ICUB_HAND_SIZE, HandModel
from kinfu_cli.grasp.plan import GraspOptions, GraspResult, plan_grasps, read_segments, support_plane


def _numbers(text: str, n: int, parameter: str) -> tuple[float, ...]:
    vals = comma_numbers(text, f"--{parameter.replace('_', '-')}") or []  # '1,,2': the list options' error
    if len(vals) != n:
        raise ConfigError(f"expected {n} comma-separated finite numbers, got {text!r}", parameter=parameter)
    return tuple(vals)


# the other hand's palm box with one --hand (commands._options.check_inapplicable)
INAPPLICABLE = tuple(Inapplicable((f"workspace-{other}",), lambda p, hand=hand: f"with --hand {hand}"
                                  if p["hand"] == hand else None, f"to the {other} hand (--hand {other} or both)")
                     for hand, other in (("right", "left"), ("left", "right")))


def _workspace(text: str | None, parameter: str) -> Workspace | None:
    if text is None:
        return None
    v = _numbers(text, 6, parameter)
    return Workspace((v[0], v[2], v[4]), (v[1], v[3], v[5]))


@click.command("grasp", short_help="Grasp poses for segmented objects from their superquadrics.")
@click.argument("segments", type=click.Path(path_type=Path))
@click.option("-o", "--output", type=OutputPath(dir_okay=False, kind="json"), default=Path("grasps.json"),
              show_default=True, help="Output JSON.")
@click.option("--hand", type=click.Choice(["right", "left", "both"]), default="both", show_default=True,
              help="Which hand; 'both' keeps the better by overlap plus reachability.")
@click.option("--segment", "segment_ids", type=int, multiple=True, help="Only this segment id (repeatable).")
@click.option("--cone", "cones", multiple=True,
              help="Orientation cone (up to three, one per hand axis): 'top', 'side' or 'AXIS:dx,dy,dz:deg' "
                   "(hand axes: z approach, x fingers, y across the palm).")
@click.option("--cone-aperture", type=float, default=PRESET_APERTURE_DEG, show_default=True,
              help="Aperture of the top / side presets (deg).")
@click.option("--workspace-right", default=None,
              help="Right palm box 'xmin,xmax,ymin,ymax,zmin,zmax' (m, world); default: the objects' box grown by "
                   "0.3 m, its -y side (robot assumed to face +x).")
@click.option("--workspace-left", default=None, help="Left palm box, as --workspace-right (default: the +y side).")
@click.option("--hand-size", default=",".join(f"{v:g}" for v in ICUB_HAND_SIZE), show_default=True,
              help="Semi-axes of the hand ellipsoid H along x (fingers), y (across the palm), z (approach) (m).")
@click.option("--hand-points", "n_points", type=int, default=48, show_default=True,
              help="L: points on the palm half of H.")
@click.option("--palm-width", type=float, default=0.06, show_default=True, help="Palm width w_p (m).")
@click.option("--thumb-length", type=float, default=0.05, show_default=True, help="Thumb length l_t (m).")
@click.option("--finger-length", type=float, default=0.07, show_default=True, help="Middle finger length l_m (m).")
@click.option("--no-lifting", is_flag=True, help="Do not stretch H to the object's largest dimension (7.2.4).")
@click.option("--pregrasp-distance", type=float, default=0.05, show_default=True,
              help="Pre-grasp: back along the approach (m).")
@click.option("--reach-weight", type=float, default=0.1, show_default=True,
              help="Weight of the palm's distance to the workspace centre in the choice of hand and part.")
@click.option("--obstacle-weight", type=float, default=1e-3, show_default=True,
              help="w4 of eq. 8.7: keeps multi-part grasps away from the other parts.")
@click.option("--starts", "n_starts", type=int, default=4, show_default=True, help="Optimiser starts per candidate.")
@click.option("--plot", type=OutputPath(dir_okay=False, kind="image"), default=None,
              help="PNG of the superquadrics, the support plane and the chosen hand ellipsoids.")
@force_option
@click.option("--json", "as_json", is_flag=True, help="Print the grasps JSON to stdout.")
@click.option("--quiet", is_flag=True, help="No progress output.")
def command(segments: Path, output: Path, hand, segment_ids, cones, cone_aperture, workspace_right, workspace_left,
            hand_size, n_points, palm_width, thumb_length, finger_length, no_lifting, pregrasp_distance,
            reach_weight, obstacle_weight, n_starts, plot, force, as_json, quiet) -> None:
    """Grasp every object of SEGMENTS (a kinfu segment segments.json, or its folder): the hand ellipsoid H
    is fitted onto the object's superquadric (thesis eq. 7.4) with SLSQP, subject to the support plane, a
    workspace box per hand and up to three orientation cones; multi-superquadric objects (segment
    --multi-sq) get one candidate per part with the other parts as obstacles (eq. 8.2). Writes per segment
    the hand pose (4x4, position, quaternion x,y,z,w), the pre-grasp pose, cost, active constraints and
    the hand chosen; a segment whose optimisation does not converge is reported with converged false
    and no pose; one whose superquadric lies outside the box of its points is skipped with a warning
    (skipped_segments). Reachability is only a proxy (distance to the workspace centre): inverse kinematics is
    the robot's job.

    \b
    Example:
      kinfu segment out/fuse/volume.npz -o out/segments
      kinfu grasp out/segments/segments.json -o out/grasps.json --plot out/grasps.png
      kinfu grasp out/segments --hand right --cone top --json --quiet
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    segments = segments / "segments.json" if segments.is_dir() else segments  # errors name the file
    claim_outputs({"output": output, "plot": plot}, [segments], force)
    # the options first, before the input is read: a bad one is named, not the input's problem
    hand_model = HandModel(_numbers(hand_size, 3, "hand_size"), n_points, palm_width, thumb_length, finger_length)
    workspaces = {h: w for h, w in (("right", _workspace(workspace_right, "workspace_right")),
                                    ("left", _workspace(workspace_left, "workspace_left"))) if w is not None}
    aperture_given = click.get_current_context().get_parameter_source("cone_aperture") != ParameterSource.DEFAULT
    if aperture_given and not any(str(c).strip().lower() in ("top", "side") for c in cones):
        raise ConfigError("sets the aperture of the 'top' / 'side' presets: give --cone top or --cone side "
                          "(an 'AXIS:dx,dy,dz:deg' cone carries its own)", parameter="cone_aperture")
    opts = GraspOptions(hand=hand, hand_model=hand_model, cones=[], workspaces=workspaces or None,
                        lifting=not no_lifting, pregrasp_distance=pregrasp_distance, reach_weight=reach_weight,
                        obstacle_weight=obstacle_weight, n_starts=n_starts, segment_ids=list(segment_ids) or None)
    opts.validate()  # all but the cones, which need the support plane's up from the input
    doc = read_segments(segments)
    plane = support_plane(doc, str(segments))
    up = plane[:3] if plane is not None else np.array([0.0, 0.0, 1.0])
    opts.cones = [parse_cone(c, up, cone_aperture) for c in cones]
    result: GraspResult = plan_grasps(doc, opts, progress=lambda ids: progress(ids, total=len(ids), desc="grasp",
                                                                               quiet=quiet),
                                      source=str(segments))
    result.source = str(segments)
    out = result.to_json()
    if plot is not None:
        from kinfu_cli.report.grasp_plot import plot_grasps

        out["plot"] = str(plot_grasps(result, plot))
    write_json(output, with_option_warnings(out))
    print_warnings(out)
    if as_json:
        click.echo(json.dumps(out, indent=2, default=float))
    elif not quiet:
        for g in out["grasps"]:
            if g["converged"]:
                p = [round(v, 3) for v in g["pose"]["position"]]
                click.echo(f"  #{g['segment']:<3} {g['hand']:<5} palm {p} overlap {g['overlap_rms_m'] * 1000:.1f} mm "
                           f"active {','.join(g['active_constraints']) or '-'}  {g['cpu_seconds']:.3f} s")
            else:
                click.echo(f"  #{g['segment']:<3} not converged: {g['reason']}")
        click.echo(f"wrote {output}")
