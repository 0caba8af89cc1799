"""The trebuchet drawn: a recorded throw as a picture (``plot_throw``) and as an animated GIF
(``animate_throw``), with the target marked."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ...animation import Frames, held, write_gif  # noqa: E402
from ...io import write_figure  # noqa: E402
from .system import TrebuchetParams  # noqa: E402


def throw_frame(ax: Any, throw: Any, i: int, target: float, wind: float) -> dict[str, Any]:
    """Draw the trebuchet and the projectile's path up to step ``i`` of a recorded throw.
    Returns the artists that move during a throw (``arm``, ``weight``, ``sling``, ``path``,
    ``stone``), for an animation to update."""
    arm, cw, proj = (np.asarray(a) for a in (throw.arm_tip, throw.counterweight, throw.projectile))
    ground = -float(TrebuchetParams().pivot_height)
    ax.axhline(ground, color="0.4", lw=1)
    ax.plot([0.0], [0.0], "ko", ms=4)
    ax.plot([0.0, 0.0], [ground, 0.0], color="0.3", lw=2)
    moving = {}
    (moving["arm"],) = ax.plot(
        [arm[i, 0], 0.0, cw[i, 0]], [arm[i, 1], 0.0, cw[i, 1]], color="#8b5a2b", lw=3
    )
    (moving["weight"],) = ax.plot([cw[i, 0]], [cw[i, 1]], "s", color="0.2", ms=8)
    on_sling = int(np.asarray(throw.phases)[i]) < 2
    sling = ([arm[i, 0], proj[i, 0]], [arm[i, 1], proj[i, 1]]) if on_sling else ([], [])
    (moving["sling"],) = ax.plot(*sling, color="0.5", lw=1)
    (moving["path"],) = ax.plot(proj[: i + 1, 0], proj[: i + 1, 1], color="C0", lw=1)
    (moving["stone"],) = ax.plot([proj[i, 0]], [proj[i, 1]], "o", color="C3", ms=5)
    ax.plot([target], [ground], marker="v", color="C2", ms=12, label=f"target {target:.1f} m")
    ax.annotate(
        f"wind {wind:+.1f} m/s",
        xy=(0.02, 0.92),
        xycoords="axes fraction",
        fontsize=9,
    )
    return moving


def plot_throw(throw: Any, target: float, wind: float, path: str | Path, title: str = "") -> Path:
    """A recorded trebuchet throw: the path, the machine at release, and the target."""
    times = np.asarray(throw.time)
    rel = np.asarray(throw.phases) >= 2
    i_rel = int(np.argmax(rel)) if rel.any() else len(times) - 1
    fig, ax = plt.subplots(figsize=(8, 3.6))
    throw_frame(ax, throw, len(times) - 1, target, wind)
    arm = np.asarray(throw.arm_tip)
    ax.plot([arm[i_rel, 0], 0.0], [arm[i_rel, 1], 0.0], color="#8b5a2b", lw=1, ls=":")
    proj = np.asarray(throw.projectile)
    x_max = max(float(np.max(proj[:, 0])), target) + 5
    ax.set_xlim(-5, x_max)
    ax.set_ylim(-2.5, max(float(np.max(proj[:, 1])) + 3, 8))
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x from the pivot (m)")
    ax.set_ylabel("height (m)")
    miss = float(throw.distance) - target
    ax.set_title(title or f"distance {float(throw.distance):.2f} m, miss {miss:+.2f} m")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return write_figure(fig, path)


def animate_throw(throw: Any, target: float, wind: float, path: str | Path, fps: int = 30) -> Path:
    """Write an animated GIF of a recorded trebuchet throw (``system.simulate``),
    played at real time until a little after landing, with the target marked. The scene is
    drawn once; each frame moves the arm, the sling, the projectile and its path."""
    times = np.asarray(throw.time)
    ended = np.asarray(throw.phases) >= 3
    last = int(np.argmax(ended)) if ended.any() else len(times) - 1
    dt = float(times[1] - times[0]) if len(times) > 1 else 1 / 60
    every = max(1, int(round(1.0 / (fps * dt))))
    arm, cw = np.asarray(throw.arm_tip), np.asarray(throw.counterweight)
    proj, phases = np.asarray(throw.projectile), np.asarray(throw.phases)
    x_max = max(float(np.max(proj[: last + 1, 0])), target) + 5
    y_max = max(float(np.max(proj[: last + 1, 1])) + 3, 8)
    indices = list(range(0, last + 1, every)) + [last]  # the landing, held by ``held``
    fig, ax = plt.subplots(figsize=(6.4, 2.8), dpi=75)
    moving = throw_frame(ax, throw, 0, target, wind)
    ax.set_xlim(-5, x_max)
    ax.set_ylim(-2.5, y_max)
    ax.set_aspect("equal", adjustable="box")
    frames, render = [], Frames().render
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
    return write_gif(frames, held(len(frames), every, dt), path)
