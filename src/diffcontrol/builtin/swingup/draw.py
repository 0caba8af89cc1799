"""A swing-up drawn: the post's three panels against time (``plot_swingup``) and the cart-pole
as an animated GIF in real time (``animate_swingup``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ...animation import Frames, held, write_gif  # noqa: E402
from ...io import write_figure  # noqa: E402
from ...plots import column_layout  # noqa: E402


def plot_swingup(recording: Any, path: str | Path, title: str = "") -> Path:
    """The post's three panels against time: pole angle (wrapped, 0 = up), cart position, force.

    ``recording`` is an ``evaluation.ContinuousRecording``.
    """
    t, y, force = recording.t, recording.y, recording.force
    # Wrapped into (-pi, pi] so that the start, hanging down at pi, does not jump to -pi.
    theta = np.pi - (np.pi - y[:, 2]) % (2 * np.pi)
    fig, axes = plt.subplots(3, 1, figsize=(7, 6.4), sharex=True)
    panels = [
        (theta, "angle θ (rad, 0 = up)", "C0"),
        (y[:, 0], "position x (m)", "C1"),
        (force, "force F (N)", "k"),
    ]
    for ax, (series, label, color) in zip(axes, panels):
        ax.plot(t, series, color=color, lw=1.5)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].axhline(0.0, color="C2", lw=1, ls="--")
    axes[0].set_yticks([-np.pi, -np.pi / 2, 0, np.pi / 2, np.pi], ["−π", "−π/2", "0", "π/2", "π"])
    axes[2].set_xlabel("time (s)")
    peak = float(np.max(np.abs(force)))
    axes[0].set_title(
        title or f"{recording.task}: peak |F| {peak:.1f} N, loss {recording.loss:.3f}"
    )
    column_layout(fig, 3)
    return write_figure(fig, path)


def animate_swingup(recording: Any, path: str | Path, fps: int = 25) -> Path:
    """Write an animated GIF of a swing-up (``evaluation.ContinuousRecording``) in real time.

    The cart is drawn to scale (0.4 m wide) with the pole's 1 m arm to its mass; the view
    follows the cart's range, and the force is printed and drawn as an arrow.
    """
    t, y, force = recording.t, recording.y, recording.force
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0 / fps
    every = max(1, int(round(1.0 / (fps * dt))))
    x_lo, x_hi = float(np.min(y[:, 0])) - 1.3, float(np.max(y[:, 0])) + 1.3
    fig, ax = plt.subplots(figsize=(max(4.0, min(9.0, 0.9 * (x_hi - x_lo))), 2.8), dpi=75)
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(-1.3, 1.3)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.plot([x_lo, x_hi], [0, 0], color="0.6", lw=1)
    cart = plt.Rectangle((0, -0.1), 0.4, 0.2, color="k")
    ax.add_patch(cart)
    (pole,) = ax.plot([], [], lw=4, color="#ca9865", solid_capstyle="round")
    (bob,) = ax.plot([], [], "o", color="#cc4d4d", ms=9)
    (arrow,) = ax.plot([], [], color="C0", lw=2)
    text = ax.text(x_lo + 0.05, 1.1, "", fontsize=8, family="monospace")
    peak = max(float(np.max(np.abs(force))), 1e-9)
    frames, render = [], Frames().render
    indices = list(range(0, len(t), every)) + [len(t) - 1]  # the end, held by ``held``
    for i in indices:
        x, theta = y[i, 0], y[i, 2]
        cart.set_x(x - 0.2)
        tip = (x + np.sin(theta), np.cos(theta))
        pole.set_data([x, tip[0]], [0.0, tip[1]])
        bob.set_data([tip[0]], [tip[1]])
        arrow.set_data([x, x + 0.8 * force[i] / peak], [-0.22, -0.22])
        text.set_text(f"t={t[i]:5.2f} s  F={force[i]:+7.2f} N")
        frames.append(render(fig))
    plt.close(fig)
    return write_gif(frames, held(len(frames), every, dt), path)
