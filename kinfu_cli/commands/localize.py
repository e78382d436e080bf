"""`kinfu localize`: 6-DoF pose of a known mesh from surface points with the Memory Unscented Particle
Filter (Vezzani 2019 ch. 4), or recognition among several meshes (ch. 5)."""

from __future__ import annotations

from pathlib import Path

import click

from kinfu_cli.commands._mupf_options import mupf_filter_options
from kinfu_cli.commands._options import OutputPath, claim_outputs, comma_items, comma_values, force_option
from kinfu_cli.commands._output import emit
from kinfu_cli.core.checks import check_number
from kinfu_cli.core.volume_file import MAX_COORDINATE_M
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.localization.localize import MAX_POINTS, localize_points
from kinfu_cli.localization.mesh_model import read_mesh
from kinfu_cli.localization.mupf import NO_REFINE, PAPER_WEIGHTS, MupfParameters
from kinfu_cli.localization.points import read_points, read_segment_points


def _prior(value: str):
    if value in ("centroid", "zero"):
        return value
    try:
        vals = [float(v) for v in comma_items(value, "--prior")]  # an empty item: the list options' error
    except ValueError:
        raise ConfigError(f"--prior {value!r}: expected 'centroid', 'zero' or x,y,z,phi,theta,psi") from None
    if len(vals) != 6:
        raise ConfigError(f"--prior {value!r}: expected 6 numbers x,y,z,phi,theta,psi")
    return vals


def _lines(doc: dict) -> list[str]:
    out = []
    for m in doc.get("recognition", {}).get("models", []):
        out.append(f"  {m['model']:<20} I_L {m['index_m'] * 1000:7.2f} mm  {m['status']}  {m['seconds']:.2f} s")
    head = f"{doc['model']}: {doc['status']}, I_L {doc['index_m'] * 1000:.2f} mm from {doc['points']} points " \
           f"(window m = {doc['window']}) in {doc['seconds']:.2f} s"
    if doc["pose"] is not None:
        p, q = doc["pose"]["position"], doc["pose"]["quaternion_xyzw"]
        head += f"\n  position {[round(v, 4) for v in p]} m, quaternion xyzw {[round(v, 4) for v in q]}"
    if "recognition" in doc:
        head = f"recognised {doc['recognition']['chosen']} (lowest I_L)\n" + "\n".join(out) + "\n" + head
    return head.splitlines()


@click.command("localize", short_help="Pose of a known mesh from surface points (MUPF); --models: recognition.")
@click.argument("model", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.argument("points", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--models", default=None, help="Comma-separated meshes a.ply,b.ply,...: recognition, the model with "
                                             "the lowest I_L wins (give no MODEL then).")
@click.option("--segments", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Points from a kinfu segment output: its segments.json (segments.ply beside it); with --segment.")
@click.option("--segment", type=int, default=None, help="Segment id in --segments.")
@click.option("-o", "--output", type=OutputPath(dir_okay=False, kind="json"), default=None,
              help="Write pose.json here.")
@click.option("--particles", type=int, default=700, show_default=True,
              help="N particles (thesis Table 4.1); about 2 kB of memory each.")
@click.option("--window", type=int, default=None, help="Memory window m (default: half the points, thesis ch. 5).")
@click.option("--sigma-p", type=float, default=0.01, show_default=True,
              help="Measurement noise std sigma_p (m); Table 4.1 uses 0.01, real tactile data 0.02.")
@click.option("--noise", type=float, default=0.002, show_default=True,
              help="Noise std of the points (m): the converged test expects I_L near 0.8 of it.")
@click.option("--max-index", type=float, default=None,
              help="Converged when I_L <= this and 90 % of the points lie within 5/3 of it (m; default 1.5 x "
                   "--noise; the thesis' test was I_L <= sigma_p).")
@click.option("--prior", default="centroid", show_default=True,
              help="Prior mean: 'centroid' (model centred on the points), 'zero' (thesis) or x,y,z,phi,theta,psi.")
@mupf_filter_options
@click.option("--max-points", type=int, default=MAX_POINTS, show_default=True,
              help="Thin more points than this to this many, in their order (the thesis runs on 100 points of a "
                   "cloud; a fused segment has thousands); 0 = all. A run estimated to filter for over 10 minutes "
                   "(particles x points x window) is refused.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option("--json", "as_json", is_flag=True, help="Print pose.json to stdout.")
@click.option("--quiet", is_flag=True, help="No progress output.")
@force_option
def command(model: Path | None, points: Path | None, models: str | None, segments: Path | None,
            segment: int | None, output: Path | None, particles: int, window: int | None, sigma_p: float,
            max_index: float | None, prior: str, beta: float, rotation: str, paper_weights: bool, no_refine: bool, noise: float, max_points: int, seed: int, as_json: bool, quiet: bool,
            force: bool) -> None:
    """Estimate the pose of the mesh MODEL (a closed triangle mesh, PLY/OBJ/STL, in its own frame) from
    POINTS on its surface: a PLY point cloud, a text file of contact points in measurement order (x y z per
    line), or a segment of a fused volume (--segments segments.json --segment ID). Memory Unscented Particle
    Filter (Vezzani 2019 Alg. 2, parameters of Table 4.1); the estimate is the MAP particle (eq. 4.28) and
    I_L (eq. 4.30, mean point-to-mesh distance) scores it; the best candidates are polished by Gauss-Newton
    first (--no-refine: not). A run whose points do not fit at the noise level (--noise, --max-index) is
    reported as not converged, without a pose. --models a.ply,b.ply runs the filter per mesh and names the one with
    the lowest I_L (ch. 5).

    \b
    Example:
      kinfu localize drill.ply touches.txt -o pose.json
      kinfu localize drill.ply --segments out/segments/segments.json --segment 3 -o pose.json
      kinfu localize --models a.ply,b.ply,c.ply touches.txt --json
    """
    if models is not None:
        if points is not None:
            raise ConfigError("--models replaces MODEL: give --models and POINTS only")
        points, model_paths = model, [Path(p) for p in comma_values(models, "--models")]
        if not model_paths:
            raise ConfigError("--models: expected comma-separated mesh files")
    else:
        if model is None:
            raise ConfigError("expected MODEL (a mesh file) or --models")
        model_paths = [model]
    if (segments is None) != (segment is None):
        raise ConfigError("--segments and --segment go together")
    if segments is not None and points is not None:
        raise ConfigError("give POINTS or --segments/--segment, not both")
    if segments is None and points is None:
        raise ConfigError("expected POINTS (a PLY or text file) or --segments/--segment")
    # the points of --segments come from the segments.ply beside it: an input too, never written over
    inputs = [*model_paths, points, segments, segments.parent / "segments.ply" if segments is not None else None]
    claim_outputs({"output": output}, inputs, force)
    check_number(sigma_p, "sigma_p", 0, MAX_COORDINATE_M, low_open=True, unit="m")
    params = MupfParameters(particles=particles, window=window, sigma_p2=sigma_p ** 2, max_index=max_index,
                            beta=beta, rotation=rotation, noise=noise, **(PAPER_WEIGHTS if paper_weights else {}),
                            **(NO_REFINE if no_refine else {}))
    params.check()
    prior_mean = _prior(prior)  # the options first: a bad one is named before an input is read
    meshes = [read_mesh(p) for p in model_paths]
    pts = read_segment_points(segments, segment) if segments is not None else read_points(points)
    result = localize_points(meshes, pts, params, prior=prior_mean, seed=seed, quiet=quiet,
                             max_points=max_points)
    doc = result.to_json()
    doc["input"] = {"models": [str(p) for p in model_paths],
                    "points": str(points) if points is not None else f"{segments} segment {segment}"}
    emit(doc, output, as_json, _lines, quiet)
