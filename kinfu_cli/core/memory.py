"""How much memory a run may plan on: the grid budget (fusion), the grids read back (volume.npz, ternary.npz), the
particle and point bounds (localization)."""

from __future__ import annotations

from kinfu_cli.core.errors import VolumeError

# the share of the memory available now that one array set may take: the rest is for the stage's work arrays
USABLE_FRACTION = 0.8


def available_bytes() -> int:
    """Memory available now (MemAvailable of /proc/meminfo; 16 GiB when it cannot be read)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 16 * 1024**3


def check_grid_memory(need: int, what: str, advice: str, parameter: str | None = None) -> None:
    """VolumeError '<what> would need up to N GB (M GB available); <advice>' when `need` bytes exceed
    USABLE_FRACTION of the memory available now: a grid made (TernaryVolume) or read (a ternary.npz) is refused
    before its arrays are allocated."""
    avail = available_bytes()
    if need > USABLE_FRACTION * avail:
        raise VolumeError(f"{what} would need up to {need / 1024**3:.1f} GB ({avail / 1024**3:.1f} GB available); "
                          f"{advice}", parameter=parameter)
