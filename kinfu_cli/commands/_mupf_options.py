"""The MUPF options `kinfu localize` and `kinfu eval localize` share (one definition, one help text)."""

from __future__ import annotations

import click


def mupf_filter_options(fn):
    """--beta, --rotation, --paper-weights and --no-refine (see README, section Localisation)."""
    fn = click.option("--no-refine", is_flag=True,
                      help="Report the MAP particle of eq. 4.28 as it is (the thesis), without polishing the best "
                           "candidates and their half-turn flips by Gauss-Newton (see README).")(fn)
    fn = click.option("--paper-weights", is_flag=True,
                      help="Weights exactly as eqs. 4.18 / 4.24 (divided by the proposal density) and the MAP over "
                           "the particles only (see README).")(fn)
    fn = click.option("--rotation", type=click.Choice(["local", "euler"]), default="local", show_default=True,
                      help="Rotation perturbation of sigma points and samples: a rotation vector at each particle, "
                           "or the thesis' Euler-angle state (see README).")(fn)
    return click.option("--beta", type=float, default=30.0, show_default=True,
                        help="Unscented transform beta (Table 4.1), 0-1000: the centre sigma point's weight in the "
                             "covariances (2 is the textbook value for Gaussian noise).")(fn)
