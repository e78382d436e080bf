"""Library parameter names whose command-line flag is not simply the option of the same Python name.

Library errors name parameters (`ConfigError(..., parameter="vfov_extra_deg")`); the CLI shows the
flag instead: this table first, else the option whose Python name is the parameter. Also the options every
writing command shares: `--force`, and the check of its outputs before any work.
"""

from __future__ import annotations

import os
from collections.abc import Iterable

import click

from kinfu_cli.core.ownership import claim_output

PARAMETER_FLAGS: dict[str, str] = {
    "vfov_extra_deg": "--vfov-extra",
    "concavity_tolerance_deg": "--concavity-tolerance",
    "sanity_angle_deg": "--sanity-angle",
    "oscillation_deg": "--oscillation",
    "region_radius": "--poi-radius",
    "modes": "--mode",
    "up_tolerance_deg": "--up-tolerance",
}


def force_option(func):
    """`--force`: write over an existing output that kinfu did not write (never over an input)."""
    return click.option("--force", is_flag=True,
                        help="Write over an existing output that kinfu did not write (an input is never written "
                             "over; kinfu replaces only its own files).")(func)


def claim_outputs(outputs: dict[str, str | os.PathLike | None], inputs: Iterable[str | os.PathLike | None],
                  force: bool) -> None:
    """Refuse, before any work, outputs that are inputs, hold an input, are empty, or exist without being
    kinfu's (unless force); keys are the commands' option names, so the error shows the flag."""
    for name, path in outputs.items():
        if path is not None:
            claim_output(path, inputs, force=force, parameter=name)
