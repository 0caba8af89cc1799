"""A planner built from its stored settings (``PlanConfig``): what ``model.json`` holds of a
planning controller, and what ``diffcontrol plan`` and ``diffcontrol.load`` build from it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import optax
from jaxtyping import PyTree

from ..errors import ConfigError
from ..settings import PlanConfig
from ._ilqr import ILQR
from ._planner import Planner, make_planner
from ._shooting import Shooting


def planner_from_config(
    task: Any,
    config: PlanConfig,
    params: PyTree | None = None,
    progress: Callable[[str], None] | None = None,
    value: Any = None,
) -> Planner:
    """The ``Planner`` that ``config`` describes, planning through ``task.step`` with
    ``params`` (default ``task.default_params()``).

    With ``config.value_grid`` the terminal cost is ``-V_0``, the value at time 0 of the task's
    grid optimum (``optimal.solve`` with that many points per state axis and
    ``config.value_levels`` actions, solved here with the same model and parameters; only
    ``V_0`` is kept). The table is solved again each time a planner is built from a file,
    rather than stored: it is deterministic given the settings, and for Pendulum's 401 grid it
    takes about half a minute on one core against 130 MB of values. A learned terminal value
    (``value``, an ``mpc.ValueNetwork`` from ``mpc.learn_value``) is stored: it is the terminal
    cost instead.

    Raises:
        ConfigError: settings the task cannot take (a loss it does not have, a value grid for
            a task without a state grid, no action bounds, both a value grid and a network).
    """
    if value is not None and config.value_grid is not None:
        raise ConfigError(
            f"value_grid={config.value_grid} and a value network are two terminal costs; "
            "drop the value grid to plan with the network"
        )
    if config.solver == "ilqr":
        solver: Any = ILQR(iterations=config.solver_iterations)
    else:
        solver = Shooting(optax.adam(config.learning_rate), iterations=config.solver_iterations)
    terminal_cost = value
    if config.value_grid is not None:
        from .. import optimal

        if progress:
            progress(
                f"solving the terminal value: grid optimum of {config.value_grid} points per "
                f"state axis, {config.value_levels} actions"
            )
        table = optimal.solve(task, config.value_grid, config.value_levels, params=params)
        first = eqx.tree_at(lambda t: t.values, table, table.values[:1])  # V_0 only

        def terminal_cost(state):
            return -first.value(0, state)

    return make_planner(
        task,
        solver,
        horizon=config.horizon,
        params=params,
        loss=config.loss,
        terminal_cost=terminal_cost,
        terminal_weight=config.terminal_weight,
        bound_starts=config.bound_starts,
    )
