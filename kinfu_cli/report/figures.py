"""Writing a matplotlib figure the way every kinfu plot is written: atomically, then closed."""

from __future__ import annotations

import os
from pathlib import Path

from kinfu_cli.core.atomic import atomic_path


def save_figure(fig, path: str | os.PathLike, dpi: int) -> Path:
    """Save `fig` as PNG at `path` atomically (a failed run leaves no half-written image) and close it."""
    import matplotlib.pyplot as plt  # heavy: only where a plot is drawn

    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    plt.close(fig)
    return path
