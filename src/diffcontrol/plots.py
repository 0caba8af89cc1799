"""PNG plots: the learning curve, the states and actions of one rollout, and what a run
directory shows of a task: its pictures (``write_figures``) and its animation (``animate_run``),
functions of a task that a task overrides as ``tasks._hooks`` says."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from . import io  # noqa: E402
from .animation import animate, can_draw  # noqa: E402
from .errors import ConfigError  # noqa: E402
from .evaluation import Recording, record_episode  # noqa: E402
from .tasks import ContinuousTask, Task  # noqa: E402
from .tasks._hooks import task_hook  # noqa: E402


def _save(fig: Any, path: str | Path) -> Path:
    return io.write_figure(fig, path)


def column_layout(fig: Any, rows: int) -> None:
    """Fixed margins (inches) for a column of ``rows`` axes sharing their x axis: room for
    a title, y labels with ticks of up to seven characters (−250000), the x label and ticks. Used
    instead of ``tight_layout`` for the pictures of every run: it measures every label by
    drawing the figure once more before it is saved (about 0.08 s a figure, one core)."""
    width, height = fig.get_size_inches()
    top, bottom, left, right, gap = 0.4, 0.6, 1.05, 0.2, 0.2
    axes_height = (height - top - bottom - (rows - 1) * gap) / rows
    fig.subplots_adjust(
        left=left / width,
        right=1 - right / width,
        top=1 - top / height,
        bottom=bottom / height,
        hspace=gap / axes_height,
    )


def learning_curve(
    metrics: dict[str, Any], path: str | Path, threshold: float | None = None
) -> Path:
    """Evaluation return (with its spread) and training loss against simulated episodes."""
    curve = metrics["curve"]
    episodes = np.array([p["simulated_episodes"] for p in curve])
    ret = np.array([p["eval_return"] for p in curve])
    std = np.array([p["eval_return_std"] for p in curve])
    loss = np.array([p["loss"] for p in curve], dtype=float)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax1.plot(episodes, ret, "o-", color="C0", label="evaluation return (simulator)")
    ax1.fill_between(episodes, ret - std, ret + std, color="C0", alpha=0.2)
    returned = [p for p in curve if p["update"] == metrics.get("returned_update")]
    if returned:
        ax1.plot(
            [returned[0]["simulated_episodes"]],
            [returned[0]["eval_return"]],
            "*",
            ms=14,
            color="C3",
            label="returned controller",
        )
    if threshold is not None:
        ax1.axhline(threshold, color="k", ls="--", lw=1, label=f"threshold {threshold:g}")
    ax1.set_ylabel("return")
    ax1.legend(loc="lower right")
    ax1.set_title(
        f"{metrics['task']}: {metrics['simulated_episodes']:.4g} simulated episodes, "
        f"{metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s)"
    )
    ok = np.isfinite(loss)
    ax2.plot(episodes[ok], loss[ok], "o-", color="C1")
    ax2.set_ylabel("training loss (window mean)")
    if ok.any() and np.all(loss[ok] > 0):
        ax2.set_yscale("log")
    ax2.set_xlabel("simulated episodes (standard length)")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    column_layout(fig, 2)
    return _save(fig, path)


def rollout(recording: Recording, task: Task, path: str | Path) -> Path:
    """States and actions of one recorded episode against time."""
    states, actions = recording.states, recording.actions
    t = np.arange(states.shape[0]) * recording.dt
    labels = list(getattr(task, "state_labels", ())) or [
        f"state {i}" for i in range(states.shape[1])
    ]
    alabels = list(getattr(task, "action_labels", ()))
    if len(alabels) != actions.shape[1]:  # e.g. the one-hot choices of a discrete head
        alabels = [f"action {i}" for i in range(actions.shape[1])]
    n = states.shape[1] + actions.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(7, 1.6 * n + 0.6), sharex=True)
    for i, ax in enumerate(axes[: states.shape[1]]):
        ax.plot(t, states[:, i], color=f"C{i}")
        ax.set_ylabel(labels[i], fontsize=8)
    for j, ax in enumerate(axes[states.shape[1] :]):
        ax.step(t[:-1], actions[:, j], where="post", color="k")
        ax.set_ylabel(alabels[j], fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(
        f"{recording.env_id} (Gymnasium), one episode: return {recording.total_return:.1f}"
    )
    column_layout(fig, n)
    return _save(fig, path)


def sweep_plot(
    rows: list[dict[str, Any]], swept: list[str], best: int, task: str, path: str | Path
) -> Path:
    """A sweep's returns: one point per member against its first swept setting other than the
    seed (its index when only seeds are swept), one colour per seed; the best member starred."""
    x_name = next((n for n in swept if n != "seed"), None)
    fig, ax = plt.subplots(figsize=(7, 4))
    seeds = sorted({r["seed"] for r in rows})
    for k, seed in enumerate(seeds):
        pts = [(i, r) for i, r in enumerate(rows) if r["seed"] == seed]
        xs = [r[x_name] if x_name else i for i, r in pts]
        ys = [r["eval_return"] if r["eval_return"] is not None else np.nan for _, r in pts]
        ax.plot(
            xs,
            ys,
            "o",
            color=f"C{k % 10}",
            alpha=0.8,
            label=f"seed {seed}" if len(seeds) <= 10 else None,
        )
    b = rows[best]
    ax.plot(
        [b[x_name] if x_name else best], [b["eval_return"]], "*", ms=16, color="C3", label="best"
    )
    if x_name and all(isinstance(r[x_name], (int, float)) and r[x_name] > 0 for r in rows):
        values = [r[x_name] for r in rows]
        if max(values) / min(values) >= 10:
            ax.set_xscale("log")
    ax.set_xlabel(x_name or "member")
    ax.set_ylabel("returned eval return (simulator)")
    ax.set_title(f"{task}: sweep of {len(rows)} runs")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


@task_hook
def write_figures(task: Any, run: Any, out: Any, animation: bool = True) -> list[str]:
    """Write the run's pictures into the directory ``out``; returns the file names.

    Default: one Gymnasium episode (reset seed 0, in the run's real system where it has one)
    as ``rollout.png`` (states, actions, rewards) and, where the task draws itself (its
    ``frames``) and ``animation``, ``rollout.gif``; none for a continuous-time task.
    """
    rec = record_episode(run.policy, task, seed=0, real=run.real_env)
    rollout(rec, task, out / "rollout.png")
    files = ["rollout.png"]
    if animation and can_draw(task):
        animate(rec, task, out / "rollout.gif")
        files.append("rollout.gif")
    return files


@write_figures.register(ContinuousTask)
def _no_figures(task: Any, run: Any, out: Any, animation: bool = True) -> list[str]:
    return []


@task_hook
def animate_run(task: Any, run: Any, path: Any, seed: int = 0, **options: Any) -> str:
    """Write an animation of the run to ``path``; returns a one-line description.

    Default: one Gymnasium episode with reset seed ``seed``, drawn by the task's ``frames``.

    Raises:
        ConfigError: the task does not draw itself.
    """
    if not can_draw(task):
        raise ConfigError(f"task {task.name!r} cannot draw itself (it defines no frames())")
    rec = record_episode(run.policy, task, seed=seed, real=run.real_env)
    animate(rec, task, path)
    return f"return {rec.total_return:.1f}, {len(rec.rewards)} steps"
