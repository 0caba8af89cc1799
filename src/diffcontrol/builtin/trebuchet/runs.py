"""The trebuchet's runs: judged by the miss over random targets, drawn as one throw."""

from __future__ import annotations

from typing import Any

from ...evaluation import evaluate_run
from ...plots import animate_run, write_figures
from .draw import animate_throw, plot_throw
from .judge import evaluate_aiming
from .task import TrebuchetAiming


@evaluate_run.register(TrebuchetAiming)
def _evaluate(task: TrebuchetAiming, run: Any, episodes: int | None = None, seed: int = 0) -> Any:
    """Miss statistics over ``episodes`` random targets (default 1,000) drawn with ``seed``,
    thrown by the run's real trebuchet where it has one (``evaluation.evaluate_aiming``)."""
    params = run.params if run.real else None
    n = episodes or task.default_eval_episodes
    return evaluate_aiming(run.policy, task, targets=n, seed=seed, params=params)


@write_figures.register(TrebuchetAiming)
def _figures(task: TrebuchetAiming, run: Any, out: Any, animation: bool = True) -> list[str]:
    """``rollout.png`` (and ``rollout.gif``): the throw at ``EXAMPLE_THROW``."""
    target, wind = task.EXAMPLE_THROW
    throw = task.throw(run, target, wind)
    plot_throw(throw, target, wind, out / "rollout.png")
    if not animation:
        return ["rollout.png"]
    animate_throw(throw, target, wind, out / "rollout.gif")
    return ["rollout.png", "rollout.gif"]


@animate_run.register(TrebuchetAiming)
def _animate(
    task: TrebuchetAiming,
    run: Any,
    path: Any,
    seed: int = 0,
    target: float | None = None,
    wind: float | None = None,
    **options: Any,
) -> str:
    """A GIF of the throw the controller aims at ``target`` m in ``wind`` m/s."""
    target = task.EXAMPLE_THROW[0] if target is None else target
    wind = task.EXAMPLE_THROW[1] if wind is None else wind
    throw = task.throw(run, target, wind)
    animate_throw(throw, target, wind, path)
    return f"distance {float(throw.distance):.2f} m, target {target:g} m"
