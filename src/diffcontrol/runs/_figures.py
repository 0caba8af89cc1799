"""What a run directory shows of a task: its pictures (``write_figures``) and its animation
(``animate_run``), the runs layer's functions of a task, which a task overrides as
``tasks._hooks`` says."""

from __future__ import annotations

from typing import Any

from ..animation import animate, can_draw
from ..errors import ConfigError
from ..evaluation import record_episode
from ..plots import rollout
from ..tasks import ContinuousTask
from ..tasks._hooks import task_hook


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
