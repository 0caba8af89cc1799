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
import numpy as np  # noqa: E402

from .evaluation import Recording  # noqa: E402
from .io import write_bytes  # noqa: E402
from .tasks import Task  # noqa: E402
from .tasks._scene import close, scene  # noqa: E402, F401  (for a task's frames)


def can_draw(task: Any) -> bool:
    """Whether ``task`` draws itself: its class defines ``frames(recording, every)``, which
    yields one matplotlib figure (``scene`` makes a blank one) or RGB array per frame."""
    return callable(getattr(type(task), "frames", None))


def write_gif(frames: list[np.ndarray], duration_ms: float | list[float], path: str | Path) -> Path:
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


def held(frames: int, every: int, dt: float) -> list[float]:
    """Per-frame durations (ms) of a clip of ``frames`` frames, each ``every`` steps of ``dt``
    s, whose last one is held for about 1 s: a held ending is drawn once, not once per frame
    of the hold (the GIF would merge the identical frames into one all the same)."""
    hold = int(round(1.0 / (every * dt)))
    frame_ms = 1000.0 * every * dt
    return [frame_ms] * (frames - 1) + [hold * frame_ms]


class Frames:
    """Renders the frames of one figure whose few artists change between frames: after the
    first two full draws, the artists that changed (matplotlib marks them ``stale``) are
    drawn over a saved background; a frame that changes anything else is drawn in full."""

    def __init__(self) -> None:
        self.fig: Any = None
        self.idle: set[Any] = set()  # stale after a full draw too: not drawn (e.g. axis off)
        self.moving: list[tuple[Any, Any]] = []
        self.background: Any = None

    def render(self, fig: Any) -> np.ndarray:
        if isinstance(fig, np.ndarray):  # a picture already (MuJoCo's renderer)
            return fig
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
    if not can_draw(task):
        raise ValueError(f"task {task.name!r} cannot draw itself (it defines no frames())")
    every = max(1, int(np.ceil(recording.states.shape[0] / max_frames)))
    render = Frames().render
    frames = [render(fig) for fig in task.frames(recording, every)]
    duration_ms = 1000.0 * recording.dt * every
    return write_gif(frames, duration_ms, path)
