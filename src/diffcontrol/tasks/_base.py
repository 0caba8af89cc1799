"""What a task is: a system, its losses, its initial-state distribution and its horizon."""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import numpy as np
from jaxtyping import Array, PRNGKeyArray, PyTree

from ..errors import ConfigError

StepLoss = Callable[[PyTree, Array, Array, Array, Array], Array]
"""``loss(params, state, action, next_state, reward) -> scalar``: the training loss of one step."""


class _TaskBase(abc.ABC):
    """What every task has: a name, a controller's shape, losses, settings and recipes."""

    name: ClassVar[str]
    summary: ClassVar[str]
    kind: ClassVar[str] = "control"
    gym_id: ClassVar[str | None] = None
    observation_size: ClassVar[int]
    action_size: ClassVar[int]
    action_head: ClassVar[str]
    action_low: ClassVar[tuple[float, ...] | None] = None
    action_high: ClassVar[tuple[float, ...] | None] = None
    obs_offset: ClassVar[tuple[float, ...] | None] = None
    obs_scale: ClassVar[tuple[float, ...] | None] = None
    losses: ClassVar[tuple[str, ...]] = ()
    state_labels: ClassVar[tuple[str, ...]] = ()
    action_labels: ClassVar[tuple[str, ...]] = ()
    env_name: ClassVar[str | None] = None

    @abc.abstractmethod
    def default_params(self) -> PyTree:
        """The nominal physical parameters (a PyTree of floats)."""

    @abc.abstractmethod
    def default_config(self) -> Any:
        """The training configuration that ``diffcontrol train NAME`` uses by default."""

    def recipes(self) -> dict[str, dict[str, Any]]:
        """Named sets of configuration overrides (``--recipe``), e.g. the 2019 original."""
        return {}

    @property
    def gym_label(self) -> str:
        """How evaluation results name the environment (``gym_id`` plus any changes)."""
        return self.gym_id or self.name

    def controller_kwargs(self) -> dict[str, Any]:
        """Keyword arguments that make an ``MLPController`` fit this task."""
        return dict(
            obs_size=self.observation_size,
            action_size=self.action_size,
            head=self.action_head,
            obs_offset=self.obs_offset,
            obs_scale=self.obs_scale,
            action_low=self.action_low,
            action_high=self.action_high,
        )

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
        kind: ``"control"`` (a sequential task evaluated in Gymnasium) or ``"aiming"`` (one
            action per situation, evaluated by its miss statistics, like the trebuchet).
        gym_id: the Gymnasium environment the task is evaluated in, or ``None``.
        episode_length: the standard episode length (Gymnasium's ``max_episode_steps``);
            ``simulated_episodes`` in ``metrics.json`` is counted in these.
        observation_size, action_size: vector sizes the controller sees and produces.
        action_head: the controller head that makes actions valid (``"tanh"``, ``"sign"``).
        action_low, action_high: bounds for bounded heads.
        obs_offset, obs_scale: the fixed observation normalisation of controllers.
        reward_threshold: the return at which the task counts as solved.
        losses: the names of the built-in training losses; the first is the default. A task
            without built-in losses leaves it empty and does not define ``step_loss``: every
            run then passes its loss, ``diffcontrol.train(task, step_loss=...)``.
        state_labels, action_labels: names with units, for plots.
        env_name: the ``Name`` of the Gymnasium environment ``diffcontrol/<Name>-v0`` that
            steps this task (``diffcontrol.envs``); ``None`` derives it from ``name``
            (``pendulum-unclipped`` -> ``PendulumUnclipped``).
    """

    episode_length: ClassVar[int]
    reward_threshold: ClassVar[float | None] = None

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

    def state_from_observation(self, observation: Array) -> Array:
        """The state that ``observe`` maps to ``observation`` (the inverse of ``observe``), so
        that a model can be fitted to recorded observations (``diffcontrol.fitting``).

        Raises:
            NotImplementedError: the task cannot reconstruct its state (the default).
        """
        raise NotImplementedError(f"task {self.name!r} cannot reconstruct a state")

    # --- configuration and the outside world ------------------------------------------------

    @abc.abstractmethod
    def default_config(self) -> Any:
        """The ``TrainConfig`` that ``diffcontrol train NAME`` uses by default."""

    def gym_action(self, action: np.ndarray) -> Any:
        """Convert a controller output to a valid action of ``gym_id``."""
        return np.asarray(action, dtype=np.float32)

    def make_gym_env(self, **kwargs: Any):
        """``gymnasium.make(gym_id, **kwargs)``; raises if the task has no Gymnasium twin."""
        import gymnasium

        if self.gym_id is None:
            raise ValueError(f"task {self.name!r} has no Gymnasium environment")
        return gymnasium.make(self.gym_id, **kwargs)

    def set_gym_state(self, env: Any, state: np.ndarray) -> None:
        """Put the Gymnasium twin ``env`` (from ``make_gym_env``) into the task's ``state``.

        ``diffcontrol.check_task`` compares ``step`` with the twin's ``env.step`` from the same
        state. The default suits Gymnasium's classic-control environments, whose state is the
        float64 array ``env.unwrapped.state``, laid out as the task's; a task whose twin keeps
        its state elsewhere, or in another layout (MuJoCo's ``set_state(qpos, qvel)``), says
        how here.

        Args:
            env: the Gymnasium environment, after ``env.reset()``.
            state: one state of the task (NumPy, shape as ``reset`` returns).
        """
        env.unwrapped.state = np.asarray(state, np.float64)


TrajectoryLoss = Callable[[Any], Array]
"""``loss(trajectory) -> scalar``: the training loss of a continuous-time task, a function of
the saved trajectory (for the swing-up, a ``SwingUpTrajectory``)."""


class StateFeedback(eqx.Module):
    """``force_fn(t, state) = controller(observe(state))[0]``, the weights as PyTree leaves."""

    controller: Any
    observe: Any = eqx.field(static=True)

    def __call__(self, t: Array, state: Array) -> Array:
        return self.controller(self.observe(state))[0]


class ContinuousTask(_TaskBase):
    """A continuous-time control task: a closed-loop ODE and a loss on its saved trajectory.

    The controller sits inside the ODE's right-hand side: ``dy/dt = f(t, y, (params, u))``
    with ``u(t, state) = controller(observe(state))``. The trainer solves the closed loop from
    ``initial_state`` over the horizon with an adaptive solver, saves ``saves`` equally spaced
    points, builds the task's trajectory object from them, and differentiates the loss of
    that trajectory through the solve (``diffcontrol.rollout.solve_closed_loop``).

    Class attributes (besides those of every task):
        kind: ``"ode"``.
        state_names: names of the mechanical state (the controller's input in ``model.json``).
        feature_names: how the observation is computed from the state, in the small language
            of ``model.json`` (a state name, ``cos(name)`` or ``sin(name)``).
    """

    kind: ClassVar[str] = "ode"
    episode_length: ClassVar[int] = 1  # one closed-loop solve
    state_names: ClassVar[tuple[str, ...]]
    feature_names: ClassVar[tuple[str, ...]]

    @abc.abstractmethod
    def initial_state(self, params: PyTree) -> Array:
        """The closed loop's initial state ``y0``."""

    @abc.abstractmethod
    def vector_field(self, t: Array, y: Array, args: tuple[PyTree, Any]) -> Array:
        """``dy/dt`` with ``args = (params, force_fn)``; ``force_fn(t, state)`` is the action."""

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

    def force_fn(self, controller: Any) -> StateFeedback:
        """The controller as the ODE's input ``(t, state) -> action``: state feedback through
        ``observe``, as a PyTree whose leaves are the controller's weights."""
        return StateFeedback(controller, self.observe)

    def controller_kwargs(self) -> dict[str, Any]:
        """As for every task, with the Glorot-uniform weights and zero biases of the post."""
        return {**super().controller_kwargs(), "init": "glorot", "final_scale": 1.0}


def _no_builtin_loss(task: _TaskBase, name: str, argument: str) -> str:
    return (
        f"task {task.name!r} has no built-in loss {name!r}; pass your loss to "
        f"diffcontrol.train(task, {argument}=...) or define {type(task).__name__}.{argument}"
    )
