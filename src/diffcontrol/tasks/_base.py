"""What a task is: a system, its losses, its initial-state distribution and its horizon."""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, PRNGKeyArray, PyTree

from .._jax_setup import FAST_COMPILE
from .._registry import env_id as own_env_id
from ..errors import ConfigError
from ..policies import NumpyPolicy, StatePolicy
from ..settings import MIN_TRANSITIONS, PlanConfig
from ._grid import GridAxis

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

    def default_plan_config(self) -> Any:
        """The planner settings (``settings.PlanConfig``) that ``diffcontrol plan NAME`` uses
        by default, options changing them; default ``PlanConfig()``. A continuous-time task
        names its control period ``dt`` here, and a task without action bounds the planner's
        ``action_bound``."""
        return PlanConfig()

    @property
    def gym_label(self) -> str:
        """How evaluation results name the environment: ``gym_id`` (plus any changes), or the
        task's own ``diffcontrol/<Name>-v0``."""
        return self.gym_id or own_env_id(self)

    # --- a run: how a trained controller is loaded and judged ---------------------------------
    # What the layers do with a run (evaluate it, draw it, animate it) are their functions
    # (``evaluation.evaluate_run``, ``plots.write_figures`` and ``animate_run``); a task
    # overrides them as ``tasks._hooks`` says.

    default_eval_episodes: ClassVar[int] = 100
    """How many episodes (or situations) the final evaluation of ``diffcontrol train`` runs."""

    final_eval_skippable: ClassVar[bool] = True
    """Whether ``--final-eval 0`` skips the final evaluation; ``False`` where it is part of
    what a run reports and its pictures are drawn from it anyway (a reference solve)."""

    fast_compile: ClassVar[Mapping[str, tuple[str, ...]]] = MappingProxyType({})
    """Options of ``_jax_setup.FAST_COMPILE`` (XLA's level 1, the older CPU emitters) that
    the programs of ``diffcontrol.train`` compile with, by program: ``"chunk"`` (the training
    updates) and ``"evaluate"`` (an evaluation point). Default: none, XLA's defaults. A built-in
    task names those under which its programs gave the defaults' bits in its default settings
    and every recipe, or, where they did not (CartPole's chunk, the trebuchet's evaluation),
    whole runs gave the same documented results (``benchmarks/compile_options.py``). Other
    settings (another ODE solver, loss or network) may round differently in the last bits: the
    options compile faster, they do not promise the defaults' bits. Read from the task's own
    class only: a subclass (another system, a fitted model) compiles with XLA's defaults
    unless it names its own."""

    def compile_options(self, program: str) -> tuple[str, ...]:
        """The ``fast_compile`` options of ``program`` (``"chunk"`` or ``"evaluate"``) that
        this task's own class declares.

        Raises:
            ConfigError: the declaration names another program, or an option that is not in
                ``_jax_setup.FAST_COMPILE``.
        """
        own = vars(type(self)).get("fast_compile", {})
        for key, names in own.items():
            if (
                key not in ("chunk", "evaluate")
                or isinstance(names, str)
                or any(n not in FAST_COMPILE for n in names)
            ):
                raise ConfigError(
                    f"task {self.name!r} declares fast_compile[{key!r}] = {names!r}; use "
                    f"'chunk' or 'evaluate' with a tuple of {', '.join(sorted(FAST_COMPILE))}"
                )
        return tuple(own.get(program, ()))

    positive_params: ClassVar[tuple[str, ...]] = ()
    """Physical parameters that must be > 0 (masses, lengths, time steps)."""
    nonnegative_params: ClassVar[tuple[str, ...]] = ()
    """Physical parameters that must be >= 0 (friction, limits)."""

    def check_params(self, params: PyTree) -> None:
        """Refuse physical parameters the simulator cannot run with: NaN anywhere, and the
        ranges of ``positive_params`` and ``nonnegative_params``.

        Raises:
            ConfigError: naming the parameter, its value and the range.
        """
        for name in (*self.positive_params, *self.nonnegative_params):
            if not hasattr(params, name):  # a fitted model's parameters: checked in its physics
                continue
            value = float(np.asarray(getattr(params, name)))
            positive = name in self.positive_params
            if np.isnan(value) or value < 0 or (positive and value == 0):
                need = "> 0" if positive else ">= 0"
                raise ConfigError(
                    f"parameter {name}={value:g} of task {self.name!r} must be {need} (the "
                    "simulator has no meaning otherwise)"
                )
        import jax

        for path, leaf in jax.tree_util.tree_leaves_with_path(params):
            if np.any(np.isnan(np.asarray(leaf, float))):
                raise ConfigError(f"the parameters of task {self.name!r} hold NaN")
            with np.errstate(over="ignore"):  # the simulator runs in float32; inf is a value
                wide = np.asarray(leaf, float)  # there (an unlimited torque), 1e300 is not
                if not np.all(np.isinf(wide) | np.isfinite(np.asarray(leaf, np.float32))):
                    name = jax.tree_util.keystr(path).lstrip(".")
                    raise ConfigError(
                        f"parameter {name}={np.asarray(leaf)} of task {self.name!r} is beyond "
                        "float32 (|x| < 3.4e38), in which the simulator runs; choose a "
                        "physical value"
                    )

    def load_policy(self, doc: dict) -> Any:
        """The NumPy policy of a ``model.json`` document (what ``diffcontrol.load`` returns).

        Default: a ``NumpyPolicy``, ``policy(obs) -> Gymnasium action``.
        """
        return NumpyPolicy(doc)

    # --- hooks of model learning (``diffcontrol.identify``): the data and the fit ----------

    fit_parameter_names: ClassVar[tuple[str, ...]] = ()
    """The physical parameters a grey-box fit (``--model params``) fits by default."""

    data_env_ids: ClassVar[tuple[str, ...]] = ()
    """Gymnasium ids, besides ``gym_id``, of environments that are this task's system with
    other physics (e.g. ``diffcontrol/PendulumFriction-v0``): ``diffcontrol record ID``
    names their columns by ``data_columns()`` too (``identify.data.known_columns``)."""

    def data_columns(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The observation and action columns (names with units) of this task's recorded
        data. Default: ``obs.0 [?]``, ... and ``action.0 [?]``, ... (``action.0 [index]`` for
        a discrete action); a task that knows its units names them, and the Gymnasium
        environments of a task whose columns are observations with known units are recorded
        under these names (``identify.data.known_columns``)."""
        obs = tuple(f"obs.{i} [?]" for i in range(self.observation_size))
        if self.action_head in ("sign", "argmax"):
            return obs, ("action.0 [index]",)
        return obs, tuple(f"action.{j} [?]" for j in range(self.action_size))

    def data_file_name(self, env_id: str | None = None) -> str:
        """The default file ``diffcontrol record`` writes (``ENV_ID`` with ``/`` as ``-``)."""
        own = env_id or self.gym_id or own_env_id(self)
        return own.replace("/", "-").replace(":", "-") + ".csv"

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

    def params_of_env(self, env_id: str, env_kwargs: dict | None = None) -> PyTree | None:
        """The physical parameters of a Gymnasium environment that is this task's system with
        other physics, or ``None`` where it is not (or they are unknown): what grid methods
        (the reference optimum of ``evaluate --optimum``) solve when a controller is judged
        on another system than the task's own.

        Default: for ``gym_id`` or one of ``data_env_ids`` whose keyword arguments all name
        fields of ``default_params()`` with numbers (e.g. ``diffcontrol/PendulumFriction-v0``
        with ``g=12, friction=0.1``), the default parameters with those values; ``None`` for
        any other environment or argument (``render_mode``, an option of the environment that
        is not a parameter). A task whose environments name their physics otherwise overrides
        it.
        """
        if env_id not in (self.gym_id, *self.data_env_ids):
            return None
        params = self.default_params()
        kwargs = dict(env_kwargs or {})
        known = {f.name for f in dataclasses.fields(params)}
        numbers = all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in kwargs.values()
        )
        if not set(kwargs) <= known or not numbers:
            return None
        names = sorted(kwargs)
        return eqx.tree_at(
            lambda p: tuple(getattr(p, n) for n in names),
            params,
            tuple(float(kwargs[n]) for n in names),
        )

    def state_from_observation(self, observation: Array) -> Array:
        """The state that ``observe`` maps to ``observation`` (the inverse of ``observe``), so
        that a model can be fitted to recorded observations (``diffcontrol.identify``).

        Raises:
            NotImplementedError: the task cannot reconstruct its state (the default).
        """
        raise NotImplementedError(f"task {self.name!r} cannot reconstruct a state")

    # --- learning by acting on the real system (``compare --real``) ---------------------------

    real_start: ClassVar[tuple[tuple[str, float], ...]] = ()
    """The wrong physics ``compare --real`` starts a grey box and a hybrid from, as
    ``(name, value)`` pairs of parameters, so that they are not handed the truth (empty: the
    nominal parameters, which are the truth when the real system is the task's own)."""

    def real_steps_per_round(self, model: str) -> int:
        """The real environment steps a round of ``compare --real`` records to learn ``model``
        (``params``, ``hybrid`` or ``neural``; episodes until the budget is spent, the last cut
        short). Default: one standard episode (``episode_length``), and at least the
        transitions a network is fitted to (``identify.MIN_TRANSITIONS``: 1,000 for a network
        alone), i.e. 200/200/1,000 on the Pendulum. A task whose episodes end early (the
        CartPole's random ones last ~20 steps) or run long chooses its own."""
        return max(self.episode_length, MIN_TRANSITIONS.get(model, 0))

    def loop_planner(self) -> Any:
        """The planner (a ``PlanConfig``) that acts through a fitted model in ``loop
        --controller plan`` and in ``compare --real``'s planner rows. Default: box-iLQR with
        H = 10 and the terminal cost ``-V_0`` of a 201-point grid optimum solved through the
        fitted model, where the task has a state grid (the Pendulum; see docs/planning.md),
        else ``default_plan_config()``."""
        if self.state_grid(self.default_params()):
            return PlanConfig(horizon=10, value_grid=201)
        return self.default_plan_config()

    # --- configuration and the outside world ------------------------------------------------

    @abc.abstractmethod
    def default_config(self) -> Any:
        """The ``TrainConfig`` that ``diffcontrol train NAME`` uses by default."""

    def gym_action(self, action: np.ndarray) -> Any:
        """Convert a controller output to a valid action of ``gym_id``."""
        return np.asarray(action, dtype=np.float32)

    def observation_space(self) -> Any:
        """The Gymnasium observation space of the task's environment (default: an unbounded
        ``Box`` of ``observation_size``)."""
        from gymnasium import spaces

        return spaces.Box(-np.inf, np.inf, (self.observation_size,), dtype=np.float32)

    def action_space(self) -> Any:
        """The Gymnasium action space: ``Discrete(2)`` for a ``sign`` head (0 pushes
        towards -1), ``Discrete(action_size)`` for an ``argmax`` head, else a ``Box`` in the
        head's bounds."""
        from gymnasium import spaces

        if self.action_head == "sign":
            return spaces.Discrete(2)
        if self.action_head == "argmax":
            return spaces.Discrete(self.action_size)
        if self.action_low is not None and self.action_high is not None:
            low, high = (np.asarray(b, np.float32) for b in (self.action_low, self.action_high))
            return spaces.Box(low, high, dtype=np.float32)
        return spaces.Box(-np.inf, np.inf, (self.action_size,), dtype=np.float32)

    def action_from_gym(self, action: Any) -> np.ndarray:
        """The task's action vector for an action of ``action_space()``: ``Discrete(2)``
        0/1 -> ``[-1]``/``[+1]``, ``Discrete(n)`` i -> one-hot, a ``Box`` action clipped."""
        if self.action_head == "sign":
            return np.array([1.0 if int(action) == 1 else -1.0])
        if self.action_head == "argmax":
            return np.eye(self.action_size)[int(action)]
        a = np.asarray(action, np.float64).reshape(self.action_size)
        if self.action_low is not None and self.action_high is not None:
            a = np.clip(a, self.action_low, self.action_high)
        return a

    def step_seconds(self, params: PyTree) -> float | None:
        """Simulated seconds per step, for time axes and recorded data: the parameter ``dt``
        or ``tau`` where the parameters have one, else ``None`` (time is then in steps)."""
        for name in ("dt", "tau"):
            if hasattr(params, name):
                # a float32 parameter: its shortest decimal (0.05, not 0.05000000074505806)
                return float(str(np.asarray(getattr(params, name))[()]))
        return None

    def make_gym_env(self, **kwargs: Any):
        """``gymnasium.make(gym_id, **kwargs)``, or of the task's own environment
        ``diffcontrol/<Name>-v0`` where it has no Gymnasium twin."""
        import gymnasium

        return gymnasium.make(self.gym_id or own_env_id(self), **kwargs)

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
        state_names: names of the mechanical state (the controller's input in ``model.json``).
        feature_names: how the observation is computed from the state, in the small language
            of ``model.json`` (a state name, ``cos(name)`` or ``sin(name)``).
    """

    episode_length: ClassVar[int] = 1  # one closed-loop solve
    state_names: ClassVar[tuple[str, ...]]
    feature_names: ClassVar[tuple[str, ...]]

    one_member_unbatched: ClassVar[bool] = False
    """Whether a population of 1 is differentiated and evaluated as one member, not under
    ``vmap``: batching Diffrax's loops is much of tracing and compiling the training chunk, so
    it is faster, but XLA then fuses the arithmetic differently and may round it differently.
    A built-in task sets it where its default settings and every recipe with a population of 1
    trained to the same weights, bit for bit (docs/benchmarks.md). Read from the task's own
    class only, like ``fast_compile``: a subclass (another system, a fitted model) keeps the
    batched programs unless it sets its own."""

    def unbatched_member(self) -> bool:
        """``one_member_unbatched`` as this task's own class declares it."""
        return bool(vars(type(self)).get("one_member_unbatched", False))

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

    # --- planning (``mpc.discretise``): a running cost and an end cost per loss ------------

    planning_losses: ClassVar[tuple[str, ...]] = ()
    """The losses a planner can plan with (``running_cost``); none by default."""

    def running_cost(self, name: str) -> Callable[[PyTree, Array, Array], Array]:
        """``rate(params, y, action)``: the cost per second of the planning loss ``name``,
        the additive counterpart of the trajectory loss of that name (``mpc.discretise``
        integrates it over each control period).

        Raises:
            ConfigError: the task defines none (the default).
        """
        raise ConfigError(f"task {self.name!r} has no planning loss {name!r} (running_cost)")

    def terminal_cost(self, name: str) -> Callable[[PyTree, Array], Array] | None:
        """``cost(params, y)`` at the end of a plan for the planning loss ``name``, or
        ``None`` (the default)."""
        return None

    def load_policy(self, doc: dict) -> Any:
        """A ``StatePolicy``: ``policy(state) -> action`` on the physical state."""
        return StatePolicy(doc)

    # --- model learning (``identify.ode``): what a system's model is -----------------------

    def data_columns(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The recorded state and action: ``state.NAME [?]`` of ``state_names`` by default."""
        return tuple(f"state.{n} [?]" for n in self.state_names), tuple(
            f"action.{j} [?]" for j in range(self.action_size)
        )

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
    task.check_params(params)
    # Converted by NumPy (the same rounding), then placed: no compiled conversion programs.
    dtype = jax.dtypes.canonicalize_dtype(float)
    return jax.tree.map(lambda x: jax.device_put(np.asarray(x, dtype=dtype)), params)
