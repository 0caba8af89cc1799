"""Animated GIFs of recorded episodes, drawn with matplotlib and written with imageio."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import imageio.v3 as iio
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .evaluation import Recording  # noqa: E402
from .io import write_bytes  # noqa: E402
from .tasks import CartPole, Pendulum, Task  # noqa: E402


def _frames_pendulum(rec: Recording, every: int):
    fig, ax = plt.subplots(figsize=(3.2, 3.2), dpi=75)
    ax.set_xlim(-1.3, 1.3)
    ax.set_ylim(-1.3, 1.3)
    ax.set_aspect("equal")
    ax.axis("off")
    (rod,) = ax.plot([], [], lw=6, color="#cc4d4d", solid_capstyle="round")
    ax.plot([0], [0], "ko", ms=5)
    text = ax.text(-1.25, 1.15, "", fontsize=8, family="monospace")
    for i in range(0, rec.states.shape[0], every):
        theta = rec.states[i, 0]
        rod.set_data([0, -np.sin(theta)], [0, np.cos(theta)])
        u = rec.actions[min(i, len(rec.actions) - 1), 0]
        text.set_text(f"t={i * rec.dt:5.2f} s  u={u:+.2f}")
        yield fig
    plt.close(fig)


def _frames_cartpole(rec: Recording, every: int):
    fig, ax = plt.subplots(figsize=(4.8, 2.4), dpi=75)
    ax.set_xlim(-2.6, 2.6)
    ax.set_ylim(-0.4, 1.3)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.plot([-2.4, 2.4], [0, 0], color="0.5", lw=1)
    for x in (-2.4, 2.4):
        ax.plot([x, x], [-0.1, 0.1], color="r", lw=1)
    cart = plt.Rectangle((0, -0.1), 0.5, 0.2, color="k")
    ax.add_patch(cart)
    (pole,) = ax.plot([], [], lw=4, color="#ca9865", solid_capstyle="round")
    text = ax.text(-2.5, 1.15, "", fontsize=8, family="monospace")
    for i in range(0, rec.states.shape[0], every):
        x, _, theta, _ = rec.states[i]
        cart.set_x(x - 0.25)
        pole.set_data([x, x + np.sin(theta)], [0.0, np.cos(theta)])
        a = rec.actions[min(i, len(rec.actions) - 1), 0]
        text.set_text(f"t={i * rec.dt:5.2f} s  push {'→' if a >= 0 else '←'}")
        yield fig
    plt.close(fig)


def _write_gif(frames: list[np.ndarray], duration_ms: float, path: str | Path) -> Path:
    """Encode RGB frames as a looping GIF (``duration_ms`` per frame) and write it atomically."""
    data = iio.imwrite("<bytes>", np.stack(frames), extension=".gif", duration=duration_ms, loop=0)
    write_bytes(path, data)
    return Path(path)


def animate(recording: Recording, task: Task, path: str | Path, max_frames: int = 250) -> Path:
    """Write an animated GIF of ``recording`` (played at real time, subsampled to at most
    ``max_frames`` frames)."""
    if hasattr(task, "frames"):  # the task draws itself (its own hook)
        drawer = task.frames
    elif isinstance(task, CartPole):
        drawer = _frames_cartpole
    elif isinstance(task, Pendulum):
        drawer = _frames_pendulum
    else:
        raise ValueError(f"no animation is defined for task {task.name!r}")
    every = max(1, int(np.ceil(recording.states.shape[0] / max_frames)))
    frames = []
    for fig in drawer(recording, every):
        fig.canvas.draw()
        frames.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    duration_ms = 1000.0 * recording.dt * every
    return _write_gif(frames, duration_ms, path)


def animate_throw(throw: Any, target: float, wind: float, path: str | Path, fps: int = 30) -> Path:
    """Write an animated GIF of a recorded trebuchet throw (``systems.trebuchet.simulate``),
    played at real time until a little after landing, with the target marked."""
    from .plots import _throw_frame

    times = np.asarray(throw.time)
    ended = np.asarray(throw.phases) >= 3
    last = int(np.argmax(ended)) if ended.any() else len(times) - 1
    dt = float(times[1] - times[0]) if len(times) > 1 else 1 / 60
    every = max(1, int(round(1.0 / (fps * dt))))
    proj = np.asarray(throw.projectile)
    x_max = max(float(np.max(proj[: last + 1, 0])), target) + 5
    y_max = max(float(np.max(proj[: last + 1, 1])) + 3, 8)
    frames = []
    hold = int(round(1.0 / (every * dt)))  # hold the landing for about 1 s
    indices = list(range(0, last + 1, every)) + [last] * hold
    fig, ax = plt.subplots(figsize=(6.4, 2.8), dpi=75)
    for i in indices:
        ax.clear()
        _throw_frame(ax, throw, i, target, wind)
        ax.set_xlim(-5, x_max)
        ax.set_ylim(-2.5, y_max)
        ax.set_aspect("equal", adjustable="box")
        ax.set_title(f"t = {times[i]:4.2f} s   x = {proj[i, 0]:6.2f} m", fontsize=9)
        fig.canvas.draw()
        frames.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    return _write_gif(frames, 1000.0 * every * dt, path)


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
    frames = []
    indices = list(range(0, len(t), every))
    indices += [len(t) - 1] * int(round(1.0 / (every * dt)))  # hold the end for about 1 s
    for i in indices:
        x, theta = y[i, 0], y[i, 2]
        cart.set_x(x - 0.2)
        tip = (x + np.sin(theta), np.cos(theta))
        pole.set_data([x, tip[0]], [0.0, tip[1]])
        bob.set_data([tip[0]], [tip[1]])
        arrow.set_data([x, x + 0.8 * force[i] / peak], [-0.22, -0.22])
        text.set_text(f"t={t[i]:5.2f} s  F={force[i]:+7.2f} N")
        fig.canvas.draw()
        frames.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    return _write_gif(frames, 1000.0 * every * dt, path)
