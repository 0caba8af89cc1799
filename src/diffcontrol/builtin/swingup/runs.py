"""The cart-pole swing-ups' runs: judged by a float64 reference solve of the closed loop, and
drawn as a cart-pole (``data.json``, ``swingup.png`` and ``rollout.gif``)."""

from __future__ import annotations

from typing import Any

from ... import io
from ...evaluation import ContinuousRecording, evaluate_run, simulate_continuous
from ...plots import animate_run, write_figures
from .draw import animate_swingup, plot_swingup
from .judge import swingup_result
from .task import CartPoleSwingUp


def reference_solve(task: CartPoleSwingUp, run: Any) -> ContinuousRecording:
    """The float64 reference solve of the run's closed loop (``simulate_continuous``),
    solved once per run: its controller inside the ODE, or a planner's sampled-data loop
    (``run.feedback``)."""
    if "reference_solve" not in run.memo:
        run.memo["reference_solve"] = simulate_continuous(
            task, run.feedback, run.params, config=run.config
        )
    return run.memo["reference_solve"]


@evaluate_run.register(CartPoleSwingUp)
def _evaluate(task: CartPoleSwingUp, run: Any, episodes: Any = None, seed: int = 0) -> Any:
    """The end state, peak force, swings and loss of the reference solve (dopri8 at 1e-9), on
    the real system where the run has one (``evaluation.swingup_result``)."""
    return swingup_result(reference_solve(task, run))


@write_figures.register(CartPoleSwingUp)
def _figures(task: CartPoleSwingUp, run: Any, out: Any, animation: bool = True) -> list[str]:
    """``data.json`` (the reference solve's time series), ``swingup.png`` (angle, position,
    force) and ``rollout.gif``."""
    rec = reference_solve(task, run)
    io.write_json(out / "data.json", rec.to_json())
    plot_swingup(rec, out / "swingup.png")
    if not animation:
        return ["data.json", "swingup.png"]
    animate_swingup(rec, out / "rollout.gif")
    return ["data.json", "swingup.png", "rollout.gif"]


@animate_run.register(CartPoleSwingUp)
def _animate(task: CartPoleSwingUp, run: Any, path: Any, seed: int = 0, **options: Any) -> str:
    """A GIF of the reference solve."""
    rec = reference_solve(task, run)
    animate_swingup(rec, path)
    return f"{rec.t[-1]:g} s, peak |F| {abs(rec.force).max():.1f} N"
