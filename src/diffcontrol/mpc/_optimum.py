"""A reference for a continuous-time task with a small state: the grid optimum of its
discretised view, run against the task's own ODE (``closed_loop_optimum``).

The task held for its control period (``discretise``) is solved by dynamic programming on the
task's ``state_grid`` (``optimal.solve``; each step's reward is minus the period's running
cost, by default the ``DwellingCost`` of the task's loss, and the end is valued by ``EndValue``).
Its greedy controller, the table's best action at the true, off-grid state at each period, held
for the period, is then solved in closed loop with the task's vector field and judged by the
task's trajectory loss from the same starts a controller is judged from
(``evaluation.evaluate_closed_loop``). It is an achievable controller, so its loss is one the
task allows (a feasibility answer next to a trained one); it optimises the running-cost view of
the loss, not the trajectory loss itself, so a controller may beat it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, PyTree

from .. import optimal
from ..evaluation import REFERENCE_ATOL, REFERENCE_RTOL, ClosedLoopResult, evaluate_closed_loop
from ._config import default_plan_config
from ._discretise import DiscretisedTask, discretise, ode_closed_loop, running_cost, terminal_cost


class GreedyHold(eqx.Module):
    """The greedy controller of a value table solved on a ``DiscretisedTask``, as a planner
    that ``ode_closed_loop`` runs: at the ``k``-th period the table's best action for the
    state at its start, held for the period. ``closed_loop`` is what
    ``evaluation.evaluate_closed_loop`` solves a sampled-data controller with."""

    table: optimal.ValueTable

    @property
    def task(self) -> DiscretisedTask:
        return self.table.task

    def initial_plan(self) -> Array:
        return jnp.zeros(())  # the index of the period, carried from one to the next

    def control(self, y: Array, k: Array) -> tuple[Array, Array, tuple]:
        return self.table.action(k.astype(jnp.int32), y), k + 1, ()

    def closed_loop(self, system: Any, params: Any, y0: Any, ts: Any) -> tuple[Any, Any, Any]:
        ys, us, _, ok = ode_closed_loop(
            self, y0, ts, params, REFERENCE_RTOL, REFERENCE_ATOL, system
        )
        return ys, us, ok


@dataclasses.dataclass(frozen=True)
class EndValue:
    """``V_T(params, y)``, the value of ending a plan at ``y``: minus the task's end cost of the
    planning loss where it declares one (``terminal_cost``), else minus the cost of one more
    period at ``y`` with the action held at the middle of its bounds, so that where the plan
    ends counts (without it every action of the last period scores the same)."""

    end: Any
    rate: Any
    dt: float
    hold: tuple[float, ...]

    def __call__(self, params: PyTree, y: Array) -> Array:
        if self.end is not None:
            return -self.end(params, y)
        return -self.dt * self.rate(params, y, jnp.asarray(self.hold, y.dtype))


@dataclasses.dataclass
class ClosedLoopOptimum:
    """The greedy controller of the grid optimum, judged as a controller of the task is
    (``result``), with the grid it was solved on."""

    result: ClosedLoopResult
    points: tuple[int, ...]
    levels: int
    dt: float

    @property
    def mean(self) -> float:
        return float(np.mean(self.result.losses))

    def gap(self, mean_loss: float) -> float | None:
        """How far ``mean_loss`` is above this reference's, as a fraction of its size (``None``
        where the reference's loss is 0)."""
        return (mean_loss - self.mean) / abs(self.mean) if self.mean else None

    def to_json(self) -> dict[str, Any]:
        return {
            "what": (
                "the greedy controller of a grid dynamic program on the task with its action "
                "held for dt (mpc.closed_loop_optimum), judged from the same starts"
            ),
            "grid_points": list(self.points),
            "action_levels": self.levels,
            "dt": self.dt,
            **{k: v for k, v in self.result.to_json().items() if k != "what"},
        }

    def summary(self) -> str:
        grid = " x ".join(map(str, self.points))
        return (
            f"grid optimum (grid {grid}, {self.levels} actions, each held {self.dt:g} s): "
            f"{self.result.summary()}"
        )


def closed_loop_optimum(
    task: Any,
    points: int = 201,
    levels: int = 41,
    *,
    params: PyTree | None = None,
    config: Any = None,
    starts: int = 1,
    seed: int = 0,
) -> ClosedLoopOptimum:
    """The grid optimum of the continuous-time ``task`` (see the module), judged by
    ``evaluate_closed_loop`` with ``config`` (default the task's), ``starts`` and ``seed``.

    The control period is the task's planning one (``default_plan_config``: the interval
    between its saved points); the table spans every period of ``config.horizon_s`` (the last
    one cut at the horizon, as ``ode_closed_loop`` runs it).

    Raises:
        ConfigError: the task has no ``state_grid`` (or one that does not fit its state), no
            action bounds, or a size out of range.
    """
    params = task.default_params() if params is None else params
    config = config or task.default_config()
    disc = discretise(task, default_plan_config(task).dt)
    horizon = max(1, math.ceil(float(config.horizon_s) / disc.dt - 1e-9))
    name = disc.losses[0]
    low, high = disc.action_low or (0.0,), disc.action_high or (0.0,)
    hold = tuple((lo + hi) / 2 for lo, hi in zip(low, high))
    final = EndValue(terminal_cost(task, name), running_cost(task, name), disc.dt, hold)
    table = optimal.solve(disc, points, levels, params=params, horizon=horizon, final=final)
    result = evaluate_closed_loop(
        task, GreedyHold(table), params, config=config, starts=starts, seed=seed
    )
    return ClosedLoopOptimum(result, tuple(table.values.shape[1:]), int(levels), disc.dt)
