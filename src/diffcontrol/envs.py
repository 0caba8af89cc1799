"""Every diffcontrol task as a Gymnasium environment: ``gymnasium.make("diffcontrol/<Name>-v0")``.

``import diffcontrol`` registers one environment per registered task
(``diffcontrol/Pendulum-v0``, ``diffcontrol/PendulumUnclipped-v0``, ``diffcontrol/CartPole-v0``,
``diffcontrol/Trebuchet-v0``, and the swing-ups below), so any reinforcement-learning library
that takes a Gymnasium environment can train on exactly the simulator that diffcontrol
differentiates through: the same ``task.reset`` distribution, the same ``task.step``
(dynamics, reward, termination) under one ``jax.jit``, the same observation, and the task's
standard episode length as Gymnasium's ``max_episode_steps``.

Spaces follow the task's action head:

- ``sign`` (CartPole): ``Discrete(2)``; action 1 is the push ``+1`` (right), 0 is ``-1``, as
  ``gym_action`` maps a controller's output.
- bounded heads (``tanh``, ``sigmoid``): ``Box(action_low, action_high)``; actions outside the
  box are clipped to it (the heads never leave it; Pendulum's plant clips the torque itself).
- ``linear`` with no bounds (the unclipped pendulum): an unbounded ``Box``.

Observations are ``float32`` in an unbounded ``Box`` of ``task.observation_size``. The state is
kept as a JAX array between steps, in JAX's default precision (``float32`` unless x64 is on).

Continuous-time tasks (the swing-ups: ``diffcontrol/CartPoleSwingUp-v0``, ``...Limited-v0``,
``...Friction-v0``) are ``ContinuousTaskEnv``: the same ODE, the action held constant over each
interval of the loss's save grid, and the episode's return minus the task's loss.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Any

import equinox as eqx
import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces

from . import _gym, _registry
from . import tasks as _tasks
from ._registry import NAMESPACE, VERSION, env_name
from .errors import ConfigError
from .tasks import Task, register_env
from .tasks import env_entry as _entry
from .tasks import supports_env as supports

__all__ = [
    "NAMESPACE",
    "VERSION",
    "ContinuousTaskEnv",
    "TaskEnv",
    "env_id",
    "env_name",
    "make_env",
    "register_all",
    "register_env",
    "supports",
]

_COMPILED: dict[str, tuple[Any, Any]] = {}


def env_id(task: Any) -> str:
    """The Gymnasium id of ``task`` (an instance or a registered name): ``diffcontrol/<Name>-v0``."""
    return _registry.env_id(_tasks.make(task) if isinstance(task, str) else task)


def _compiled(task: Task, params: Any, nominal: bool) -> tuple[Any, Any]:
    """Jitted ``reset(key)`` and ``step(state, action)`` of ``task`` with ``params`` built in.

    The parameters are closed over (constants of the compiled programs): fewer arguments to
    flatten per call makes a step much cheaper to dispatch. The programs of the
    nominal parameters are shared by every environment of the task, so making many
    environments (an evaluation pool) compiles once.
    """
    if nominal and task.name in _COMPILED and _COMPILED[task.name][0] is type(task):
        return _COMPILED[task.name][1]

    def reset(key):
        state = task.reset(key, params)
        return state, task.observe(state)

    def step(state, action):
        next_state, reward, terminated = task.step(params, state, action.astype(state.dtype))
        return next_state, task.observe(next_state), reward, terminated

    fns = (jax.jit(reset), jax.jit(step))
    if nominal:
        _COMPILED[task.name] = (type(task), fns)
    return fns


class TaskEnv(gymnasium.Env):
    """A discrete-time diffcontrol task stepped from NumPy through its jitted ``task.step``.

    Args:
        task: a registered task name (``"pendulum"``) or a ``Task`` instance.
        params: the task's physical parameters (a PyTree like ``task.default_params()``);
            the nominal ones when omitted.

    The environment itself never truncates: ``gymnasium.make("diffcontrol/<Name>-v0")`` wraps
    it in a ``TimeLimit`` of ``task.episode_length`` steps, as Gymnasium does for its own
    environments. ``reset(seed=s)`` draws the JAX key of ``task.reset`` from the environment's
    seeded NumPy generator, so a seed gives the same start every time (not the same start as
    Gymnasium's own environment with that seed: the two draw differently).

    Raises:
        UnknownTaskError: ``task`` is not a registered name.
        ConfigError: the task is not a discrete-time ``Task``.
    """

    metadata = {"render_modes": []}

    def __init__(self, task: Task | str, params: Any = None):
        if isinstance(task, str):
            task = _tasks.make(task)
        if not supports(task):
            raise ConfigError(
                f"task {getattr(task, 'name', task)!r} is not a discrete-time Task; a "
                "continuous-time task is stepped by ContinuousTaskEnv"
            )
        self.task = task
        p = task.default_params() if params is None else params
        self.params = jax.tree.map(lambda x: jnp.asarray(x, dtype=float), p)
        self.observation_space = _gym.observation_space(task)
        self.action_space = _gym.action_space(task)
        self._reset, self._step = _compiled(task, self.params, params is None)
        self.state: jax.Array | None = None

    def task_action(self, action: Any) -> np.ndarray:
        """The task's action vector for a Gymnasium action (``action_from_gym``)."""
        return _gym.action_from_gym(self.task, action)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        key = jax.random.PRNGKey(int(self.np_random.integers(0, 2**31 - 1)))
        self.state, obs = self._reset(key)
        return np.asarray(obs, np.float32), {}

    def step(self, action: Any):
        if self.state is None:
            raise RuntimeError("call reset() before step()")
        self.state, obs, reward, terminated = self._step(self.state, self.task_action(action))
        obs, reward, terminated = jax.device_get((obs, reward, terminated))
        return np.asarray(obs, np.float32), float(reward), bool(terminated), False, {}


def register_all() -> list[str]:
    """Register every registered task as a Gymnasium environment (again: a task registered
    with ``diffcontrol.register`` is registered at once). Returns the ids."""
    return [register_env(t) for t in map(_tasks.make, _tasks.names()) if _entry(t) is not None]


# ---------------------------------------------------------------------------------------------
# Continuous-time tasks (the swing-ups): the same ODE, the action held over each save interval.


class ContinuousTaskEnv(gymnasium.Env):
    """A continuous-time diffcontrol task as a Gymnasium environment, with a zero-order hold.

    An episode is the task's closed loop over ``horizon_s`` from its (deterministic) initial
    state, cut into the ``saves - 1`` intervals of the save grid that the loss sees; each step
    holds the action (the force, N) constant over one interval and integrates the task's own
    vector field over it (Tsit5 at rtol 1e-6, atol 1e-8). The observation is the task's
    (``(cos theta, sin theta, theta_dot)`` for the swing-ups; ``info["state"]`` has the full
    state). The reward is 0 until the last step, which returns minus the task's default loss
    of the recorded trajectory: the episode's return is exactly ``-loss``, the number
    diffcontrol minimises. The loss's force at save ``k`` is the action held after it (the
    last save repeats the last action).

    What differs from the differentiable version: there the controller acts continuously
    inside the ODE; here an agent can only act once per interval (0.02 s for the 1 s swing-up,
    0.2 s for the 10 s one). With a constant force both give the same trajectory (a test
    checks that).

    Args:
        task: a registered continuous-time task name or instance.
        params: its physical parameters; the nominal ones when omitted.
        max_force: the action space's bound (N); the swing-up's force is unbounded, but RL
            needs a box (the unconstrained swing-up peaks at about 63 N).
    """

    metadata = {"render_modes": []}

    def __init__(self, task: Any, params: Any = None, max_force: float = 100.0):
        import diffrax

        if isinstance(task, str):
            task = _tasks.make(task)
        self.task = task
        self.config = task.default_config()
        p = task.default_params() if params is None else params
        self.params = jax.tree.map(lambda x: jnp.asarray(x, dtype=float), p)
        self.dt = self.config.horizon_s / (self.config.saves - 1)
        self.observation_space = spaces.Box(
            -np.inf, np.inf, (task.observation_size,), dtype=np.float32
        )
        self.action_space = spaces.Box(-max_force, max_force, (task.action_size,), np.float32)
        self._loss = jax.jit(self._episode_loss)

        def advance(y, force):
            sol = diffrax.diffeqsolve(
                diffrax.ODETerm(task.vector_field),
                diffrax.Tsit5(),
                0.0,
                self.dt,
                None,
                y,
                args=(self.params, _Hold(force)),
                stepsize_controller=diffrax.PIDController(rtol=1e-6, atol=1e-8),
                max_steps=4096,
            )
            return sol.ys[-1]

        self._advance = jax.jit(advance)
        self._observe = jax.jit(task.observe)
        self._ys: list[np.ndarray] = []
        self._forces: list[float] = []

    def _episode_loss(self, ys, forces):
        ts = jnp.linspace(0.0, self.config.horizon_s, self.config.saves)
        traj = self.task.trajectory(self.params, lambda obs: jnp.zeros((1,)), ts, ys)
        traj = eqx.tree_at(lambda tr: tr.force, traj, forces.astype(ys.dtype))
        return self.task.trajectory_loss(self.task.losses[0])(traj)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        # the task's reset distribution (by default its one initial state), keyed by the seed
        key = jax.random.PRNGKey(int(self.np_random.integers(0, 2**31 - 1)))
        y = self.task.reset(key, self.params)
        self._ys, self._forces = [np.asarray(y)], []
        return self._obs(y), {"state": np.asarray(y[:4])}

    def _obs(self, y) -> np.ndarray:
        return np.asarray(self._observe(jnp.asarray(y)[:4]), np.float32)

    def step(self, action: Any):
        if not self._ys:
            raise RuntimeError("call reset() before step()")
        force = float(np.clip(np.asarray(action, np.float64).reshape(-1)[0], *self._bounds()))
        y = self._advance(jnp.asarray(self._ys[-1]), jnp.asarray(force, float))
        self._ys.append(np.asarray(y))
        self._forces.append(force)
        done = len(self._ys) == self.config.saves
        reward = 0.0
        if done:
            forces = np.asarray(self._forces + self._forces[-1:])
            reward = -float(self._loss(jnp.asarray(np.stack(self._ys)), jnp.asarray(forces)))
        return self._obs(y), reward, False, done, {"state": np.asarray(y[:4])}

    def _bounds(self) -> tuple[float, float]:
        return float(self.action_space.low[0]), float(self.action_space.high[0])


class _Hold(eqx.Module):
    """A force held constant: ``force_fn(t, state) = force``."""

    force: Any

    def __call__(self, t, state):
        return self.force


def _import_typed_module(env_id: str) -> None:
    """Import the module of a ``module:Env-v0`` id from the current directory as well, as a
    task's import path is (``tasks.resolve``): such an id reaches here only as the user typed
    it (``--env``, ``record``). An id read from a file has passed
    ``identify.fitted.checked_env_id``, which refuses a module not imported already, so
    nothing is imported here because a file named it."""
    module, sep, _ = env_id.partition(":")
    if not sep or not module or module in sys.modules:
        return
    here = os.getcwd()
    added = here not in sys.path and "" not in sys.path
    if added:
        sys.path.insert(0, here)
    try:
        importlib.import_module(module)
    except Exception as e:  # noqa: BLE001 - any failure of the user's module is reported
        raise ConfigError(
            f"cannot make the environment {env_id!r}: importing {module!r} raised "
            f"{type(e).__name__}: {' '.join(str(e).split())[:200]}; check the module path (run "
            "from the directory that holds it, or install its package)"
        ) from None
    finally:
        if added:
            sys.path.remove(here)


def make_env(env_id: str, env_kwargs: dict | None = None) -> gymnasium.Env:
    """``gymnasium.make(env_id, **env_kwargs)``, with an unknown id as a ``ConfigError``; the
    module of a ``module:Env-v0`` id is found in the current directory too.

    Raises:
        ConfigError: Gymnasium does not know ``env_id`` (the message lists a few it does), or
            refuses ``env_kwargs``.
    """
    _import_typed_module(env_id)
    try:
        return gymnasium.make(env_id, **(env_kwargs or {}))
    except gymnasium.error.Error as e:
        import difflib

        close = difflib.get_close_matches(env_id, list(gymnasium.registry), n=3)
        near = f"close ones: {', '.join(close)}; " if close else ""
        raise ConfigError(
            f"unknown Gymnasium environment {env_id!r} ({' '.join(str(e).split())}); {near}"
            '`python -c "import gymnasium; gymnasium.pprint_registry()"` lists the known ones'
        ) from None
    except ImportError as e:  # the module before ':' of an id the user named
        raise ConfigError(
            f"cannot make the environment {env_id!r}: {type(e).__name__}: "
            f"{' '.join(str(e).split())[:200]}; check the module path (run from the directory "
            "that holds it, or install its package)"
        ) from None
    except (TypeError, ValueError, AttributeError) as e:  # an argument of the wrong kind
        msg = " ".join(str(e).split())[:200]
        raise ConfigError(f"{env_id} does not take the arguments {env_kwargs} ({msg})") from None
