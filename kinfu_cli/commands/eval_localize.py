"""`kinfu eval localize`: MUPF vs Scaling Series vs RANSAC + ICP on generated meshes (thesis Table 4.2
protocol) and recognition among six near-identical blocks (ch. 5)."""

from __future__ import annotations

from pathlib import Path

import click

from kinfu_cli.commands._mupf_options import mupf_filter_options
from kinfu_cli.commands._options import (Inapplicable, OutputPath, check_inapplicable, claim_outputs, comma_values,
                                         force_option)
from kinfu_cli.commands._output import QUIET_HELP, emit
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.localization.evaluate import METHODS, check_recognition, evaluate_localization, \
    evaluate_recognition, format_localization_table
from kinfu_cli.localization.mupf import NO_REFINE, PAPER_WEIGHTS, MupfParameters
from kinfu_cli.localization.shapes import SIMULATION_SHAPES

group = "eval"


def _names(text: str, allowed, option: str) -> list[str]:
    vals = comma_values(text, option)
    bad = [v for v in vals if v not in allowed]
    if bad or not vals:
        raise ConfigError(f"{option} {text!r}: expected some of {', '.join(allowed)}")
    return vals


def _no_mupf(p: dict) -> str | None:
    """When no MUPF runs: --methods without mupf and no recognition (which runs MUPF per model)."""
    methods = {m.strip() for m in p["methods"].split(",")}
    return None if "mupf" in methods or p["recognition_trials"] != 0 else \
        "with --methods without mupf and --recognition-trials 0"


# options given where they do nothing (commands._options.check_inapplicable)
INAPPLICABLE = (
    Inapplicable(("recognition-points",), lambda p: "with --recognition-trials 0" if p["recognition_trials"] == 0
                 else None, "to the recognition trials (--recognition-trials 1 or more)"),
    Inapplicable(("particles", "beta", "rotation", "paper-weights", "no-refine"), _no_mupf,
                 "to MUPF (--methods with mupf, or the recognition trials)"),
)


@click.command("localize", short_help="MUPF vs Scaling Series vs RANSAC+ICP (thesis Table 4.2); recognition (ch. 5).")
@click.option("--shapes", default=",".join(SIMULATION_SHAPES), show_default=True, help="Generated meshes to use.")
@click.option("--trials", type=int, default=50, show_default=True, help="Trials per shape (thesis: 50).")
@click.option("--methods", default=",".join(METHODS), show_default=True, help="Methods to run on each trial.")
@click.option("--noise", type=float, default=0.002, show_default=True, help="Measurement noise std (m).")
@click.option("--particles", type=int, default=700, show_default=True, help="MUPF particles N.")
@click.option("--recognition-trials", type=int, default=1, show_default=True,
              help="Recognition trials per object (0: skip recognition).")
@click.option("--recognition-points", type=int, default=170, show_default=True,
              help="Points per recognition trial (thesis: about 170).")
@mupf_filter_options
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option("-o", "--output", type=OutputPath(dir_okay=False, kind="json"), default=None,
              help="Write the results as JSON here.")
@click.option("--json", "as_json", is_flag=True, help="Print the results JSON to stdout instead of the table.")
@click.option("--quiet", is_flag=True, help=QUIET_HELP)
@force_option
def command(shapes: str, trials: int, methods: str, noise: float, particles: int, recognition_trials: int,
            recognition_points: int, beta: float, rotation: str, paper_weights: bool, no_refine: bool, seed: int, output: Path | None, as_json: bool, quiet: bool,
            force: bool) -> None:
    """Reproduce the thesis' simulation (Vezzani 2019 Table 4.2): on generated box, tetrahedron, cleaner,
    robot and helmet meshes, --trials true poses offset 0.05-0.1 m along one axis and 45-90 deg about one
    axis, L noisy surface points (Table 4.3, window m as there); MUPF (Table 4.1 parameters), the Scaling
    Series and open3d RANSAC (FPFH) + ICP on the same points. Success: ADD-S <= 1 cm and, for the
    non-symmetric cleaner and robot, within 30 deg and 2 cm of the true pose. Then recognition (ch. 5): six
    near-identical blocks, MUPF per model, the lowest I_L names the object.

    \b
    Example:
      kinfu eval localize --trials 50 -o localize.json
      kinfu eval localize --shapes robot --trials 5 --methods mupf --recognition-trials 0
    """
    check_inapplicable(click.get_current_context(), INAPPLICABLE)
    names = _names(shapes, list(SIMULATION_SHAPES), "--shapes")
    meths = _names(methods, list(METHODS), "--methods")
    claim_outputs({"output": output}, [], force)
    params = MupfParameters(particles=particles, beta=beta, rotation=rotation,
                            noise=noise if noise > 0 else MupfParameters.noise,
                            **(PAPER_WEIGHTS if paper_weights else {}), **(NO_REFINE if no_refine else {}))
    params.check()
    check_recognition(recognition_trials, recognition_points, params)
    doc = evaluate_localization(names, trials=trials, noise=noise, params=params, methods=meths, seed=seed,
                                quiet=quiet)
    if recognition_trials:
        doc["recognition"] = evaluate_recognition(trials=recognition_trials, n_points=recognition_points,
                                                  params=params, seed=seed, quiet=quiet)
    doc["warnings"] = []
    emit(doc, output, as_json, lambda d: format_localization_table(d).splitlines(), quiet)
