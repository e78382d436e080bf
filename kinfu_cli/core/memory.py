"""How much memory a run may plan on: the grid budget (fusion), the particle and point bounds (localization)."""

from __future__ import annotations


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
