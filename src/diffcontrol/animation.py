"""Animated GIFs of recorded episodes, drawn with matplotlib and written with Pillow.

A frame redraws only what moved (matplotlib's blitting: the artists a task changed since the
last frame are drawn over a background drawn once), and the GIF is encoded with one palette
for all frames (taken from a few of them), which is what makes it quick to write.
"""

from __future__ import annotations

import io as _io
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .evaluation import Recording  # noqa: E402
from .io import write_bytes  # noqa: E402
from .tasks import Task  # noqa: E402


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


def _write_gif(
    frames: list[np.ndarray], duration_ms: float | list[float], path: str | Path
) -> Path:
    """Encode RGB frames as a looping GIF (``duration_ms`` per frame, or one per frame) and
    write it atomically.

    One adaptive palette of up to 255 colours, from up to 8 frames spread over the clip, maps
    every frame without dithering: flat drawings need no more, and encoding skips a
    quantisation per frame.
    """
    from PIL import Image

    sample = frames[:: max(1, len(frames) // 8)][:8]
    palette = Image.fromarray(np.concatenate(sample, axis=0)).quantize(
        colors=255, method=Image.Quantize.MEDIANCUT
    )
    images = [
        Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames
    ]
    buffer = _io.BytesIO()
    images[0].save(
        buffer,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=(
            [max(1, round(d)) for d in duration_ms]
            if isinstance(duration_ms, list)
            else max(1, round(duration_ms))
        ),
        loop=0,
    )
    write_bytes(path, buffer.getvalue())
    return Path(path)


def _held(frames: int, every: int, dt: float) -> list[float]:
    """Per-frame durations (ms) of a clip of ``frames`` frames, each ``every`` steps of ``dt``
    s, whose last one is held for about 1 s: a held ending is drawn once, not once per frame
    of the hold (the GIF would merge the identical frames into one all the same)."""
    hold = int(round(1.0 / (every * dt)))
    frame_ms = 1000.0 * every * dt
    return [frame_ms] * (frames - 1) + [hold * frame_ms]


class _Frames:
    """Renders the frames of one figure whose few artists change between frames: after the
    first two full draws, the artists that changed (matplotlib marks them ``stale``) are
    drawn over a saved background; a frame that changes anything else is drawn in full."""

    def __init__(self) -> None:
        self.fig: Any = None
        self.idle: set[Any] = set()  # stale after a full draw too: not drawn (e.g. axis off)
        self.moving: list[tuple[Any, Any]] = []
        self.background: Any = None

    def render(self, fig: Any) -> np.ndarray:
        canvas = fig.canvas
        changed = [
            (ax, a) for ax in fig.axes for a in ax.get_children() if a.stale and a not in self.idle
        ]
        if fig is self.fig and self.background is not None and set(changed) <= set(self.moving):
            canvas.restore_region(self.background)
            for ax, artist in self.moving:
                ax.draw_artist(artist)
        elif fig is self.fig and self.background is None and changed:
            self.moving = sorted(changed, key=lambda pair: pair[1].get_zorder())
            for _, artist in self.moving:  # drawn apart from the background from now on
                artist.set_animated(True)
            canvas.draw()
            self.background = canvas.copy_from_bbox(fig.bbox)
            for ax, artist in self.moving:
                ax.draw_artist(artist)
        else:
            for _, artist in self.moving:
                artist.set_animated(False)
            self.fig, self.moving, self.background = fig, [], None
            canvas.draw()
            self.idle = {a for ax in fig.axes for a in ax.get_children() if a.stale}
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def animate(recording: Recording, task: Task, path: str | Path, max_frames: int = 150) -> Path:
    """Write an animated GIF of ``recording`` (played at real time, subsampled to at most
    ``max_frames`` frames)."""
    if not task.can_draw:
        raise ValueError(f"task {task.name!r} cannot draw itself (it defines no frames())")
    every = max(1, int(np.ceil(recording.states.shape[0] / max_frames)))
    render = _Frames().render
    frames = [render(fig) for fig in task.frames(recording, every)]
    duration_ms = 1000.0 * recording.dt * every
    return _write_gif(frames, duration_ms, path)


def animate_throw(throw: Any, target: float, wind: float, path: str | Path, fps: int = 30) -> Path:
    """Write an animated GIF of a recorded trebuchet throw (``systems.trebuchet.simulate``),
    played at real time until a little after landing, with the target marked. The scene is
    drawn once; each frame moves the arm, the sling, the projectile and its path."""
    from .plots import _throw_frame

    times = np.asarray(throw.time)
    ended = np.asarray(throw.phases) >= 3
    last = int(np.argmax(ended)) if ended.any() else len(times) - 1
    dt = float(times[1] - times[0]) if len(times) > 1 else 1 / 60
    every = max(1, int(round(1.0 / (fps * dt))))
    arm, cw = np.asarray(throw.arm_tip), np.asarray(throw.counterweight)
    proj, phases = np.asarray(throw.projectile), np.asarray(throw.phases)
    x_max = max(float(np.max(proj[: last + 1, 0])), target) + 5
    y_max = max(float(np.max(proj[: last + 1, 1])) + 3, 8)
    indices = list(range(0, last + 1, every)) + [last]  # the landing, held by ``_held``
    fig, ax = plt.subplots(figsize=(6.4, 2.8), dpi=75)
    moving = _throw_frame(ax, throw, 0, target, wind)
    ax.set_xlim(-5, x_max)
    ax.set_ylim(-2.5, y_max)
    ax.set_aspect("equal", adjustable="box")
    frames, render = [], _Frames().render
    for i in indices:
        moving["arm"].set_data([arm[i, 0], 0.0, cw[i, 0]], [arm[i, 1], 0.0, cw[i, 1]])
        moving["weight"].set_data([cw[i, 0]], [cw[i, 1]])
        on_sling = int(phases[i]) < 2
        moving["sling"].set_data(*(([arm[i, 0], proj[i, 0]], [arm[i, 1], proj[i, 1]])
                                   if on_sling else ([], [])))  # fmt: skip
        moving["path"].set_data(proj[: i + 1, 0], proj[: i + 1, 1])
        moving["stone"].set_data([proj[i, 0]], [proj[i, 1]])
        ax.set_title(f"t = {times[i]:4.2f} s   x = {proj[i, 0]:6.2f} m", fontsize=9)
        frames.append(render(fig))
    plt.close(fig)
    return _write_gif(frames, _held(len(frames), every, dt), path)


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
    frames, render = [], _Frames().render
    indices = list(range(0, len(t), every)) + [len(t) - 1]  # the end, held by ``_held``
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
    return _write_gif(frames, _held(len(frames), every, dt), path)
