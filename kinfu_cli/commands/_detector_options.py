"""The GMM-AS and ZVC options shared by `kinfu poi` and `kinfu eval poi`, and their parsing.

The option names are those of attention.detect.detector_params, so library errors about a detector
parameter show the flag of the same name.
"""

from __future__ import annotations

import click

from kinfu_cli.attention.detect import detector_params
from kinfu_cli.commands._options import Inapplicable
from kinfu_cli.core.errors import ConfigError
from kinfu_cli.core.pois import DEFAULT_RADIUS

#: Python names of the options `detector_options` adds.
DETECTOR_OPTIONS = ("poi_threshold", "neighbours", "bic_threshold", "max_components", "selection", "time_scale",
                    "reg_space", "reg_time", "saliency", "threshold_mode", "resample", "noise_floor",
                    "merge_distance", "literal",
                    "zvc_half_width", "zvc_threshold", "zvc_r1", "zvc_r2", "zvc_rule", "zvc_relative",
                    "radius")

#: the options only GMM-AS reads, and only ZVC (long flags without the dashes); --literal and --radius are both's
GMM_AS_OPTIONS = ("poi-threshold", "neighbours", "bic-threshold", "max-components", "selection", "time-scale",
                  "reg-space", "reg-time", "saliency", "threshold-mode", "resample", "noise-floor", "merge-distance")
ZVC_OPTIONS = ("zvc-half-width", "zvc-rule", "zvc-relative", "zvc-threshold", "zvc-r1", "zvc-r2")
#: what --literal sets to the paper's values (GmmActivitySaliency.LITERAL; ZVC's ratio rule with ZVCTh 1.72)
LITERAL_OPTIONS = ("poi-threshold", "time-scale", "reg-space", "reg-time", "saliency", "threshold-mode", "resample",
                   "noise-floor", "merge-distance", "zvc-rule", "zvc-threshold", "zvc-relative")


def _ratio_rule(p: dict) -> str | None:
    """How ZVC's ratio rule was chosen, when it was (--zvc-relative is the relative rule's)."""
    if p["zvc_rule"] == "ratio":
        return "with --zvc-rule ratio"
    return "with --zvc-threshold (ZVC's ratio rule)" if p["zvc_rule"] is None and p["zvc_threshold"] is not None \
        else None


def detector_inapplicable(algorithms) -> tuple[Inapplicable, ...]:
    """The detector options' rules for commands._options.check_inapplicable; algorithms(params): the detectors
    that run ({"gmm-as"}, {"zvc"} or both)."""
    return (
        Inapplicable(GMM_AS_OPTIONS, lambda p: None if "gmm-as" in algorithms(p) else "with --algorithm zvc",
                     "to GMM-AS (--algorithm gmm-as)"),
        Inapplicable(ZVC_OPTIONS, lambda p: None if "zvc" in algorithms(p) else "with --algorithm gmm-as",
                     "to ZVC (--algorithm zvc)"),
        Inapplicable(LITERAL_OPTIONS, lambda p: "with --literal" if p["literal"] else None,
                     "without --literal (it sets the paper's values)"),
        Inapplicable(("zvc-relative",), _ratio_rule, "to ZVC's relative rule (--zvc-rule relative, the default)"),
        Inapplicable(("zvc-threshold",), lambda p: "with --zvc-rule relative" if p["zvc_rule"] == "relative"
                     else None, "to ZVC's ratio rule (--zvc-rule ratio)"),
    )


def _time_scale(value: str) -> str | float:
    if value.strip().lower() == "duration":
        return "duration"
    try:
        return float(value)
    except ValueError:
        raise ConfigError(f"--time-scale: expected 'duration' or units per second, got {value!r}") from None


def detector_options(f):
    """The GMM-AS and ZVC parameters as options (shared by `kinfu poi` and `kinfu eval poi`)."""
    opts = [
        click.option("--poi-threshold", default=1.5, show_default=True, type=float,
                     help="GMM-AS POITh: saliency must exceed this x the neighbours' mean (paper Table 2: 2.5; "
                          "Tables 5-6: 1.5)."),
        click.option("--neighbours", default=2, show_default=True, type=int, help="GMM-AS Lambda: neighbours each side."),
        click.option("--bic-threshold", default=0.0, show_default=True, type=float,
                     help="GMM-AS BICTh: stop when BIC > min BIC + this."),
        click.option("--max-components", default=15, show_default=True, type=int, help="GMM-AS Kmax."),
        click.option("--selection", default="first-minimum", show_default=True,
                     type=click.Choice(["first-minimum", "best"]), help="GMM-AS: first BIC minimum or best of 1..Kmax."),
        click.option("--time-scale", default="duration", show_default=True,
                     help="GMM-AS 4th coordinate: 'duration' (t normalised to 0..1) or units per second (1 = s)."),
        click.option("--reg-space", default=0.005, show_default=True, type=float,
                     help="GMM-AS spatial std floor (m) added to covariances."),
        click.option("--reg-time", default=0.03, show_default=True, type=float,
                     help="GMM-AS time std floor, in --time-scale units."),
        click.option("--saliency", default="precision", show_default=True,
                     type=click.Choice(["precision", "literal", "weight", "conditional"]),
                     help="GMM-AS saliency reading (see kinfu_cli/attention/gmm_as.py; 'literal' = eq. 13 on "
                          "the spatial covariance)."),
        click.option("--threshold-mode", default="available", show_default=True,
                     type=click.Choice(["available", "literal"]),
                     help="GMM-AS: mean of existing neighbours, or sum / 2 Lambda as printed in Alg. 3."),
        click.option("--resample", default=300, show_default=True, type=int,
                     help="GMM-AS: resample each trajectory to this many samples (0 = raw samples)."),
        click.option("--noise-floor", default=1.0, show_default=True, type=float,
                     help="GMM-AS: raise the floor to this x the estimated sensor noise, denoising first (0 = off)."),
        click.option("--merge-distance", default=0.05, show_default=True, type=float,
                     help="GMM-AS: consecutive POI Gaussians closer than this (m) are one POI (one long pause "
                          "split in two); 0 = one POI per Gaussian as in the paper."),
        click.option("--literal", is_flag=True,
                     help="The paper read literally: GMM-AS on raw samples, t in s, 1 mm floor, eq. 13 on the "
                          "spatial covariance, POITh 2.5, sum / 2 Lambda, no merging; ZVC's ratio rule with ZVCTh 1.72. Overrides those options."),
        click.option("--zvc-half-width", default=4, show_default=True, type=int, help="ZVC B (filter width 2B+1)."),
        click.option("--zvc-rule", default=None, type=click.Choice(["relative", "ratio"]),
                     help="ZVC slow-sample rule: 'relative' (local speed < --zvc-relative x the task's 95th "
                          "percentile speed) or 'ratio' (the paper's eq. 15 with --zvc-threshold) [default: "
                          "relative, or ratio when --zvc-threshold is given]."),
        click.option("--zvc-relative", default=0.28, show_default=True, type=float,
                     help="ZVC relative rule: fraction of the task's 95th percentile speed (chosen by "
                          "leave-one-user-out, see attention/zvc.py)."),
        click.option("--zvc-threshold", default=None, type=float,
                     help="ZVC ZVCTh of the paper's absolute ratio rule; giving it selects that rule (paper 1.72; "
                          "1.5 re-calibrated on users 1+4) [default: 1.5 under --zvc-rule ratio]."),
        click.option("--zvc-r1", default=0.10, show_default=True, type=float, help="ZVC inner radius r1 (m)."),
        click.option("--zvc-r2", default=0.25, show_default=True, type=float, help="ZVC outer radius r2 (m)."),
        click.option("--radius", default=DEFAULT_RADIUS, show_default=True, type=float,
                     help="Region radius of each POI (m)."),
    ]
    for opt in reversed(opts):
        f = opt(f)
    return f


def detector_params_from(kw: dict) -> dict[str, dict]:
    """{"gmm-as": {...}, "zvc": {...}} constructor keywords from the parsed options (removed from kw)."""
    options = {name: kw.pop(name) for name in DETECTOR_OPTIONS}
    options["time_scale"] = _time_scale(options["time_scale"])
    return detector_params(**options)
