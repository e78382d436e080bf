"""Library parameter names whose command-line flag is not simply the option of the same Python name.

Library errors name parameters (`ConfigError(..., parameter="vfov_extra_deg")`); the CLI shows the
flag instead: this table first, else the option whose Python name is the parameter.
"""

PARAMETER_FLAGS: dict[str, str] = {
    "vfov_extra_deg": "--vfov-extra",
    "concavity_tolerance_deg": "--concavity-tolerance",
    "region_radius": "--poi-radius",
    "modes": "--mode",
}
