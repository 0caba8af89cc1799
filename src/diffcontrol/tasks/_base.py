"""What a task is: a system, its losses, its initial-state distribution and its horizon.

The task classes are the contract a system fulfils, nothing more. What a layer does with a
task (evaluate it, draw it, fit a model of it, plan through it, load its policy, record its
data, step its Gymnasium twin) is that layer's function, with a default there that a task
changes by defining a method of the same name (``tasks._hooks``). The functions below are the
tasks layer's own: the parameters a task accepts, and the controller and closed-loop input
that fit it.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, PRNGKeyArray, PyTree

from ..errors import ConfigError
from ._grid import GridAxis
from ._hooks import task_hook

StepLoss = Callable[[PyTree, Array, Array, Array, Array], Array]
"""``loss(params, state, action, next_state, reward) -> scalar``: the training loss of one step."""


class _TaskBase(abc.ABC):
    """What every task has: a name, a controller's shape, losses, settings and recipes."""

    name: ClassVar[str]
    summary: ClassVar[str]
    gym_id: ClassVar[str | None] = None
    observation_size: ClassVar[int]
    action_size: ClassVar[int]
    action_head: ClassVar[str]
    action_low: ClassVar[tuple[float, ...] | None] = None
    action_high: ClassVar[tuple[float, ...] | None] = None
    obs_offset: ClassVar[tuple[float, ...] | None] = None
    obs_scale: ClassVar[tuple[float, ...] | None] = None
    losses: ClassVar[tuple[str, ...]] = ()

    @abc.abstractmethod
    def default_params(self) -> PyTree:
        """The nominal physical parameters (a PyTree of floats)."""

    @abc.abstractmethod
    def default_config(self) -> Any:
        """The training configuration that ``diffcontrol train NAME`` uses by default."""

    def recipes(self) -> dict[str, dict[str, Any]]:
        """Named sets of configuration overrides (``--recipe``), e.g. the 2019 original."""
        return {}

    def __repr__(self) -> str:
        return f"<task {self.name}>"


class Task(_TaskBase):
    """A discrete-time control task.

    Subclasses are stateless singletons: everything that varies between calls (physical
    parameters, states, keys) is an argument, so every method is a pure function that can be
    ``jit``ted, ``vmap``ped and differentiated.

    Class attributes:
        name: the registry name (``diffcontrol list``).
        summary: one line for ``diffcontrol list``.
        gym_id: the Gymnasium environment the task is evaluated in, or ``None``.
        episode_length: the standard episode length (Gymnasium's ``max_episode_steps``);
            ``simulated_episodes`` in ``metrics.json`` is counted in these.
        observation_size, action_size: vector sizes the controller sees and produces.
        action_head: the controller head that makes actions valid (``"tanh"``, ``"sign"``).
        action_low, action_high: bounds for bounded heads.
        obs_offset, obs_scale: the fixed observation normalisation of controllers.
        losses: the names of the built-in training losses; the first is the default. A task
            without built-in losses leaves it empty and does not define ``step_loss``: every
            run then passes its loss, ``diffcontrol.train(task, step_loss=...)``.

    Optional declarations that layers read where a task makes them: ``reward_threshold`` (the
    return at which the task counts as solved), ``env_name`` (the ``Name`` of its environment
    ``diffcontrol/<Name>-v0``, else derived from ``name``), ``state_labels`` and
    ``action_labels`` (names with units, for plots), ``positive_params`` and
    ``nonnegative_params`` (``check_params``), and those of the layers' hooks (docs/own-system.md).
    """

    episode_length: ClassVar[int]

    # --- the differentiable simulator -------------------------------------------------------

    @abc.abstractmethod
    def reset(self, key: PRNGKeyArray, params: PyTree) -> Array:
        """Sample an initial state from the task's reset distribution."""

    @abc.abstractmethod
    def step(self, params: PyTree, state: Array, action: Array) -> tuple[Array, Array, Array]:
        """Advance one step: returns ``(next_state, reward, terminated)``.

        Differentiable in ``params``, ``state`` and ``action`` wherever the system is.
        ``terminated`` is a boolean with no derivative.
        """

    @abc.abstractmethod
    def observe(self, state: Array) -> Array:
        """The observation the controller sees (Gymnasium's observation)."""

    def step_loss(self, name: str) -> StepLoss:
        """The built-in training loss ``name`` (one of ``losses``) of one step.

        Raises:
            ConfigError: the task has no built-in losses (the default); pass the loss to
                ``diffcontrol.train(task, step_loss=...)``.
        """
        raise ConfigError(_no_builtin_loss(self, name, "step_loss"))

    def state_grid(self, params: PyTree) -> tuple[GridAxis, ...] | None:
        """The state space as a grid for grid methods, or ``None`` (the default): no grid.

        ``diffcontrol.optimal`` solves a task that returns one by dynamic programming on that
        grid (the reference optimum that controllers' returns are compared with). Return one
        ``GridAxis`` per entry of the state (as ``reset`` and ``step`` lay it out), only where
        the state is small (two entries: a grid of 801 x 801 points is cheap, one of four
        dimensions is not) and every reachable state lies in the ranges (a periodic axis wraps,
        a bounded one clamps). The actions are gridded between ``action_low`` and
        ``action_high``, so a task that has a grid also has action bounds.

        Args:
            params: the physical parameters (the ranges may depend on them, e.g. a speed clip).
        """
        del params
        return None

    # --- configuration and the outside world ------------------------------------------------

    @abc.abstractmethod
    def default_config(self) -> Any:
        """The ``TrainConfig`` that ``diffcontrol train NAME`` uses by default."""


TrajectoryLoss = Callable[[Any], Array]
"""``loss(trajectory) -> scalar``: the training loss of a continuous-time task, a function of
the saved trajectory (for the swing-up, a ``SwingUpTrajectory``)."""


class ContinuousTask(_TaskBase):
    """A continuous-time control task: a closed-loop ODE and a loss on its saved trajectory.

    The controller sits inside the ODE's right-hand side: ``dy/dt = f(t, y, (params, u))``
    with ``u(t, state) = controller(observe(state))``. The trainer solves the closed loop from
    ``initial_state`` over the horizon with an adaptive solver, saves ``saves`` equally spaced
    points, builds the task's trajectory object from them, and differentiates the loss of
    that trajectory through the solve (``diffcontrol.rollout.solve_closed_loop``).

    Class attributes (besides those of every task):
        state_names: names of the mechanical state (the controller's input in ``model.json``).

    A task that a saved controller should run on without JAX declares ``feature_names``: how
    the observation is computed from the state, in the small language of ``model.json`` (a
    state name, ``cos(name)`` or ``sin(name)``).
    """

    episode_length: ClassVar[int] = 1  # one closed-loop solve
    state_names: ClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def initial_state(self, params: PyTree) -> Array:
        """The closed loop's initial state ``y0``."""

    def reset(self, key: PRNGKeyArray, params: PyTree) -> Array:
        """Sample an initial state from the task's reset distribution; training with
        ``ODETrainConfig(starts=N)`` draws ``N`` of them per update. Default: the one
        ``initial_state`` (override it to train a controller that copes with perturbed
        starts)."""
        del key
        return self.initial_state(params)

    @abc.abstractmethod
    def vector_field(self, t: Array, y: Array, args: tuple[PyTree, Any]) -> Array:
        """``dy/dt`` with ``args = (params, force_fn)``; ``force_fn(t, state)`` is the action
        (a scalar for a task with one action, as the force of ``examples/continuous_task.py``)."""

    @abc.abstractmethod
    def observe(self, state: Array) -> Array:
        """The controller's input computed from the mechanical state."""

    @abc.abstractmethod
    def trajectory(self, params: PyTree, controller: Any, ts: Array, ys: Array) -> Any:
        """The trajectory object that losses see, from the saved times and states."""

    def trajectory_loss(self, name: str) -> TrajectoryLoss:
        """The built-in loss ``name`` (one of ``losses``) of a saved trajectory.

        Raises:
            ConfigError: the task has no built-in losses (the default); pass the loss to
                ``diffcontrol.train(task, trajectory_loss=...)``.
        """
        raise ConfigError(_no_builtin_loss(self, name, "trajectory_loss"))


def _no_builtin_loss(task: _TaskBase, name: str, argument: str) -> str:
    return (
        f"task {task.name!r} has no built-in loss {name!r}; pass your loss to "
        f"diffcontrol.train(task, {argument}=...) or define {type(task).__name__}.{argument}"
    )


@task_hook
def check_params(task: Any, params: PyTree) -> None:
    """Refuse physical parameters the simulator cannot run with: NaN anywhere, values beyond
    float32, and the ranges the task declares in ``positive_params`` (must be > 0: masses,
    lengths, time steps) and ``nonnegative_params`` (must be >= 0: friction, limits).

    Raises:
        ConfigError: naming the parameter, its value and the range.
    """
    positive = tuple(getattr(task, "positive_params", ()))
    for name in (*positive, *getattr(task, "nonnegative_params", ())):
        if not hasattr(params, name):  # a fitted model's parameters: checked in its physics
            continue
        value = float(np.asarray(getattr(params, name)))
        if np.isnan(value) or value < 0 or (name in positive and value == 0):
            need = "> 0" if name in positive else ">= 0"
            raise ConfigError(
                f"parameter {name}={value:g} of task {task.name!r} must be {need} (the "
                "simulator has no meaning otherwise)"
            )
    for path, leaf in jax.tree_util.tree_leaves_with_path(params):
        if np.any(np.isnan(np.asarray(leaf, float))):
            raise ConfigError(f"the parameters of task {task.name!r} hold NaN")
        with np.errstate(over="ignore"):  # the simulator runs in float32; inf is a value
            wide = np.asarray(leaf, float)  # there (an unlimited torque), 1e300 is not
            if not np.all(np.isinf(wide) | np.isfinite(np.asarray(leaf, np.float32))):
                name = jax.tree_util.keystr(path).lstrip(".")
                raise ConfigError(
                    f"parameter {name}={np.asarray(leaf)} of task {task.name!r} is beyond "
                    "float32 (|x| < 3.4e38), in which the simulator runs; choose a "
                    "physical value"
                )


def controller_kwargs(task: Task | ContinuousTask) -> dict[str, Any]:
    """Keyword arguments that make an ``MLPController`` fit ``task``: its sizes, head, bounds
    and observation normalisation; for a continuous-time task also the Glorot-uniform weights
    and zero biases of the post."""
    kwargs = dict(
        obs_size=task.observation_size,
        action_size=task.action_size,
        head=task.action_head,
        obs_offset=task.obs_offset,
        obs_scale=task.obs_scale,
        action_low=task.action_low,
        action_high=task.action_high,
    )
    if isinstance(task, ContinuousTask):
        kwargs.update(init="glorot", final_scale=1.0)
    return kwargs


def task_params(
    task: Task | ContinuousTask, overrides: tuple[tuple[str, float], ...] = ()
) -> PyTree:
    """The task's nominal parameters with ``overrides`` applied, as JAX arrays."""
    params = task.default_params()
    for name, value in overrides:
        if not hasattr(params, name):
            fields = [f.name for f in dataclasses.fields(params)]
            raise ConfigError(
                f"task {task.name!r} has no parameter {name!r}; its parameters are {', '.join(fields)}"
            )
        params = eqx.tree_at(lambda p, n=name: getattr(p, n), params, value)
    check_params(task, params)
    # Converted by NumPy (the same rounding), then placed: no compiled conversion programs.
    dtype = jax.dtypes.canonicalize_dtype(float)
    return jax.tree.map(lambda x: jax.device_put(np.asarray(x, dtype=dtype)), params)
