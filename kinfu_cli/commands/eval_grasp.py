"""`kinfu eval grasp`: constraint satisfaction, hand-object overlap, penetration and time of `kinfu grasp` on
generated objects (thesis Table 7.2 sizes, composite objects) and on segmented synthetic scenes."""

from __future__ import annotations

from pathlib import Path

import click

from kinfu_cli.commands._options import OutputPath, claim_outputs, comma_items, comma_values, force_option
from kinfu_cli.commands._output import QUIET_HELP, emit
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.progress import progress
from kinfu_cli.grasp.evaluate import evaluate_grasping, format_grasp_table
from kinfu_cli.grasp.plan import GraspOptions

group = "eval"


@click.command("grasp", short_help="Grasp constraint satisfaction, overlap, penetration and time.")
@click.option("--hand", type=click.Choice(["right", "left", "both"]), default="right", show_default=True,
              help="Hand(s) per object (the thesis times one hand).")
@click.option("--conditions", default="none,top,side", show_default=True,
              help="Cone presets to test, comma-separated: none, top, side.")
@click.option("--yaws", type=int, default=2, show_default=True, help="Random yaws per generated object.")
@click.option("--scenes", default="0,1", show_default=True,
              help="Seeds of the segmented synthetic tabletop scenes ('' for none).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the generated object poses.")
@click.option("-o", "--output", type=OutputPath(dir_okay=False, kind="json"), default=None,
              help="Write the results as JSON here.")
@click.option("--json", "as_json", is_flag=True, help="Print the results JSON to stdout instead of the table.")
@click.option("--quiet", is_flag=True, help=QUIET_HELP)
@force_option
def command(hand: str, conditions: str, yaws: int, scenes: str, seed: int, output: Path | None, as_json: bool,
            quiet: bool, force: bool) -> None:
    """Grasp every generated object (Table 7.2 sizes as boxes, cylinders and ellipsoids, plus a bottle, a T
    and an L of two parts each) under each cone condition, and every segment of the generated tabletop
    scenes; from each reported pose recompute the support-plane and obstacle penetration, cones and
    workspace (share satisfying every constraint), the overlap (RMS distance of H's L points to the
    object) and the CPU time per object beside the time of a superquadric fit in the same run.

    \b
    Example:
      kinfu eval grasp --scenes 0 -o grasp_eval.json
      kinfu eval grasp --conditions none --yaws 1 --scenes '' --json
    """
    conds = tuple(comma_values(conditions, "--conditions"))
    bad = [c for c in conds if c not in ("none", "top", "side")]
    if bad or not conds:
        raise ConfigError(f"--conditions: expected none, top or side, got {conditions!r}")
    try:
        seeds = tuple(int(s) for s in comma_items(scenes, "--scenes"))  # '' for none, as the help says
    except ValueError:
        raise ConfigError(f"--scenes: expected comma-separated integers, got {scenes!r}") from None
    if not 1 <= yaws <= 20:
        raise ConfigError(f"--yaws: expected 1..20, got {yaws}")
    claim_outputs({"output": output}, [], force)
    doc = evaluate_grasping(GraspOptions(hand=hand), conditions=conds, yaws=yaws, scenes=seeds, seed=seed,
                            progress=lambda xs: progress(xs, total=len(xs), desc="eval grasp", quiet=quiet))
    emit(doc, output, as_json, lambda d: format_grasp_table(d).splitlines(), quiet)
