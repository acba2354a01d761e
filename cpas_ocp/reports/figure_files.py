"""Writing a matplotlib figure to a PNG file: every figure of the reports, one way."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def write_figure(fig: plt.Figure, title: str | None, path: Path) -> Path:
    """Title (if any), lay out, write at 110 dpi and close a figure; returns `path`.

    `tight_layout` places the axes and leaves a placeholder layout engine on the figure,
    for which `savefig` would draw the whole figure once more (with the renderer off)
    before drawing it to the file.  The axes are already placed, so the engine is
    dropped first: the same pixels, without that draw."""
    if title is not None:
        fig.suptitle(title)
    fig.tight_layout()
    fig.set_layout_engine(None)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
