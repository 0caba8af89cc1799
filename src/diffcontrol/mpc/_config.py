"""A planner built from its stored settings (``PlanConfig``): what ``model.json`` holds of a
planning controller, and what ``diffcontrol plan`` and ``diffcontrol.load`` build from it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import optax
from jaxtyping import PyTree

from .. import optimal
from ..errors import ConfigError
from ..settings import PlanConfig
from ..tasks._base import ContinuousTask
from ..tasks._hooks import task_hook
from ._discretise import DiscretisedTask, discretise
from ._ilqr import ILQR
from ._planner import RELAXATIONS, Planner, make_planner
from ._shooting import Shooting


@task_hook
def default_plan_config(task: Any) -> PlanConfig:
    """The planner settings that ``diffcontrol plan NAME`` uses by default, options changing
    them; default ``PlanConfig()``. A continuous-time task names its control period ``dt``
    here, and a task without action bounds the planner's ``action_bound``."""
    return PlanConfig()


@default_plan_config.register(ContinuousTask)
def _sampled_data(task: Any) -> PlanConfig:
    """A continuous-time task's control period ``dt``: the interval between the saved points
    of its training configuration (``horizon_s / (saves - 1)``), the grid its loss sees."""
    config = task.default_config()
    return PlanConfig(dt=config.horizon_s / (config.saves - 1))


@task_hook
def loop_planner(task: Any) -> PlanConfig:
    """The planner that acts through a fitted model in ``loop --controller plan`` and in
    ``compare --real``'s planner rows. Default: box-iLQR with H = 10 and the terminal cost
    ``-V_0`` of a 201-point grid optimum solved through the fitted model, where the task has a
    state grid (the Pendulum; see docs/planning.md), else ``default_plan_config``."""
    if task.state_grid(task.default_params()):
        return PlanConfig(horizon=10, value_grid=201)
    return default_plan_config(task)


def plans_best(task: Any) -> bool:
    """Whether the task's best controller through a model is its planner: action bounds, a
    state grid and a loop planner with a grid value (the Pendulum; the mountain car, with a
    grid, declines one). ``loop`` acts with it by default, and ``compare`` adds its planning
    rows."""
    bounded = task.action_low is not None and task.action_high is not None
    grid = task.state_grid(task.default_params())
    return bool(bounded and grid and loop_planner(task).value_grid)


def for_task(config: PlanConfig, task: Any) -> PlanConfig:
    """``config`` with what it leaves open (``dt``, ``action_bound``: ``None``) taken from
    the task's own planning defaults (``default_plan_config``): what ``diffcontrol plan``
    stores, so that a stored planner does not change with them."""
    own = default_plan_config(task)
    return config.replace(
        **{n: getattr(own, n) for n in ("dt", "action_bound") if getattr(config, n) is None}
    )


def planner_from_config(
    task: Any,
    config: PlanConfig,
    params: PyTree | None = None,
    progress: Callable[[str], None] | None = None,
    value: Any = None,
) -> Planner:
    """The ``Planner`` that ``config`` describes, planning through ``task.step`` with
    ``params`` (default ``task.default_params()``).

    A continuous-time task (a ``ContinuousTask``) is planned through its discrete-time view
    ``discretise(task, config.dt, config.substeps)`` (the action held for ``dt`` seconds,
    RK4), with the task's end cost of the planning loss (``terminal_cost``) as the
    terminal cost unless a value network replaces it; ``dt`` and ``action_bound`` left
    ``None`` are the task's (``for_task``). Run such a planner against the ODE
    itself with ``ode_episode``, or wrap it as a ``SampledPlannerPolicy``.

    With ``config.value_grid`` the terminal cost is ``-V_0``, the value at time 0 of the task's
    grid optimum (``optimal.solve`` with that many points per state axis and
    ``config.value_levels`` actions, solved here with the same model and parameters; only
    ``V_0`` is kept). The table is solved again each time a planner is built from a file,
    rather than stored: it is deterministic given the settings, and a fine grid's values would
    dwarf the file. A learned terminal value
    (``value``, an ``mpc.ValueNetwork`` from ``mpc.learn_value``) is stored: it is the terminal
    cost instead.

    Raises:
        ConfigError: settings the task cannot take (a loss it does not have, a value grid for
            a task without a state grid, no action bounds, both a value grid and a network,
            ``dt`` or ``substeps`` for a discrete-time task, no ``dt`` for a continuous one).
    """
    config = for_task(config, task)
    if isinstance(task, ContinuousTask):
        if config.dt is None:
            raise ConfigError(
                f"task {task.name!r} is continuous-time: its planner needs dt, the control "
                "period in seconds (--dt 0.05, PlanConfig(dt=0.05))"
            )
        task = discretise(task, config.dt, config.substeps)
    elif config.dt is not None or config.substeps != 1:
        raise ConfigError(
            f"dt={config.dt}, substeps={config.substeps}: task {task.name!r} is discrete-time "
            "and steps at its own rate; leave --dt and --substeps out"
        )
    bounds = None
    if config.action_bound is not None:
        bounds = (
            (-config.action_bound,) * task.action_size,
            (config.action_bound,) * task.action_size,
        )
    elif task.action_low is None and task.action_head not in RELAXATIONS:
        raise ConfigError(
            f"task {task.name!r} has no action bounds; a planner needs them: pass "
            "--action-bound B (PlanConfig(action_bound=B)), the actions then within +-B"
        )
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
        if progress:
            progress(
                f"solving the terminal value: grid optimum of {config.value_grid} points per "
                f"state axis, {config.value_levels} actions"
            )
        first = optimal.solve_first(task, config.value_grid, config.value_levels, params=params)

        def terminal_cost(state):
            return -first.value(0, state)

    if terminal_cost is None and isinstance(task, DiscretisedTask):
        terminal_cost = task.terminal_cost(config.loss or task.losses[0], params)
    return make_planner(
        task,
        solver,
        horizon=config.horizon,
        params=params,
        loss=config.loss,
        terminal_cost=terminal_cost,
        terminal_weight=config.terminal_weight,
        bound_starts=config.bound_starts,
        bounds=bounds,
    )
