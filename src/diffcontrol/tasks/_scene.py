"""Blank drawings for a task's ``frames`` (matplotlib, imported when a task first draws)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def scene(width_in: float, height_in: float, xlim: tuple, ylim: tuple, dpi: int = 75):
    """A blank drawing for a task's ``frames``: a figure of the given size (inches) with one
    axes of equal aspect over ``xlim`` x ``ylim`` and no ticks. Returns ``(fig, ax)``; the
    caller closes it (``close(fig)``) when its frames are done."""
    fig, ax = plt.subplots(figsize=(width_in, height_in), dpi=dpi)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.axis("off")
    return fig, ax


def close(fig) -> None:
    """Release a figure made by ``scene``."""
    plt.close(fig)
