"""Writing a matplotlib figure the way every kinfu plot is written: atomically, then closed."""

from __future__ import annotations

import os
from pathlib import Path

from kinfu_cli.core.atomic import atomic_path


def save_figure(fig, path: str | os.PathLike, dpi: int) -> Path:
    """Save `fig` at `path` atomically (a failed run leaves no half-written image) and close it: in the format
    its suffix names when matplotlib writes that format (.png, .pdf, .svg, ...), else as PNG (a path without a
    suffix or with another one, e.g. a plot path views.json, was a traceback after all the work was done)."""
    import matplotlib.pyplot as plt  # heavy: only where a plot is drawn

    path = Path(path)
    suffix = path.suffix.lower().lstrip(".")
    fmt = suffix if suffix in fig.canvas.get_supported_filetypes() else "png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=fmt)
    plt.close(fig)
    return path
