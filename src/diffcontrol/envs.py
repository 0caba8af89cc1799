"""Every diffcontrol task as a Gymnasium environment: ``gymnasium.make("diffcontrol/<Name>-v0")``.

``import diffcontrol`` registers one environment per registered discrete-time task
(``diffcontrol/Pendulum-v0``, ``diffcontrol/PendulumUnclipped-v0``, ``diffcontrol/CartPole-v0``,
``diffcontrol/Trebuchet-v0``), so any reinforcement-learning library that takes a Gymnasium
environment can train on exactly the simulator that diffcontrol differentiates through: the
same ``task.reset`` distribution, the same ``task.step`` (dynamics, reward, termination) under
one ``jax.jit``, the same observation, and the task's standard episode length as Gymnasium's
``max_episode_steps``.

Spaces follow the task's action head:

- ``sign`` (CartPole): ``Discrete(2)``; action 1 is the push ``+1`` (right), 0 is ``-1``, as
  ``task.gym_action`` maps a controller's output.
- bounded heads (``tanh``, ``sigmoid``): ``Box(action_low, action_high)``; actions outside the
  box are clipped to it (the heads never leave it; Pendulum's plant clips the torque itself).
- ``linear`` with no bounds (the unclipped pendulum): an unbounded ``Box``.

Observations are ``float32`` in an unbounded ``Box`` of ``task.observation_size``. The state is
kept as a JAX array between steps, in JAX's default precision (``float32`` unless x64 is on).

Tasks of other kinds (a continuous-time task solved with Diffrax, say) are skipped by
``register_all``: only subclasses of ``diffcontrol.tasks.Task`` whose ``kind`` is in
``SUPPORTED_KINDS`` become environments.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces

from . import tasks as _tasks
from .errors import ConfigError
from .tasks import Task

NAMESPACE = "diffcontrol"
VERSION = 0
SUPPORTED_KINDS = ("control", "aiming")
"""Task kinds that step one action at a time through ``Task.step`` (see ``Task.kind``)."""


def env_name(task: Task) -> str:
    """The ``Name`` of ``diffcontrol/<Name>-v0`` for ``task`` (``task.env_name`` or derived)."""
    if getattr(task, "env_name", None):
        return str(task.env_name)
    return "".join(part.capitalize() for part in task.name.replace("_", "-").split("-"))


def env_id(task: Task | str) -> str:
    """The Gymnasium id of ``task`` (an instance or a registered name): ``diffcontrol/<Name>-v0``."""
    if isinstance(task, str):
        task = _tasks.make(task)
    return f"{NAMESPACE}/{env_name(task)}-v{VERSION}"


def supports(task: Any) -> bool:
    """Whether ``task`` can be stepped as a Gymnasium environment by ``TaskEnv``."""
    return isinstance(task, Task) and task.kind in SUPPORTED_KINDS


_COMPILED: dict[str, tuple[Any, Any]] = {}


def _compiled(task: Task, params: Any, nominal: bool) -> tuple[Any, Any]:
    """Jitted ``reset(key)`` and ``step(state, action)`` of ``task`` with ``params`` built in.

    The parameters are closed over (constants of the compiled programs): fewer arguments to
    flatten per call makes a step several times cheaper to dispatch. The programs of the
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
        ConfigError: the task is of a kind that cannot be stepped one action at a time.
    """

    metadata = {"render_modes": []}

    def __init__(self, task: Task | str, params: Any = None):
        if isinstance(task, str):
            task = _tasks.make(task)
        if not supports(task):
            raise ConfigError(
                f"task {getattr(task, 'name', task)!r} of kind {getattr(task, 'kind', '?')!r} "
                f"cannot be a step-by-step Gymnasium environment; supported kinds: "
                f"{', '.join(SUPPORTED_KINDS)}"
            )
        self.task = task
        p = task.default_params() if params is None else params
        self.params = jax.tree.map(lambda x: jnp.asarray(x, dtype=float), p)
        self.observation_space = spaces.Box(
            -np.inf, np.inf, (task.observation_size,), dtype=np.float32
        )
        self._discrete = task.action_head == "sign"
        if self._discrete:
            self.action_space = spaces.Discrete(2)
            self._low = self._high = None
        elif task.action_low is not None and task.action_high is not None:
            self._low = np.asarray(task.action_low, np.float32)
            self._high = np.asarray(task.action_high, np.float32)
            self.action_space = spaces.Box(self._low, self._high, dtype=np.float32)
        else:
            self._low = self._high = None
            self.action_space = spaces.Box(-np.inf, np.inf, (task.action_size,), dtype=np.float32)

        self._reset, self._step = _compiled(task, self.params, params is None)
        self.state: jax.Array | None = None

    def task_action(self, action: Any) -> np.ndarray:
        """The task's action vector for a Gymnasium action (``Discrete`` 0/1 -> ``[-1]``/``[+1]``)."""
        if self._discrete:
            return np.array([1.0 if int(action) == 1 else -1.0])
        a = np.asarray(action, np.float64).reshape(self.task.action_size)
        if self._low is not None:
            a = np.clip(a, self._low, self._high)
        return a

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


def register_env(task: Task) -> str:
    """Register ``task`` as ``diffcontrol/<Name>-v0`` (again, if already there); returns the id.

    Raises:
        ConfigError: the task's kind cannot be stepped one action at a time.
    """
    if not supports(task):
        raise ConfigError(
            f"task {task.name!r} of kind {task.kind!r} has no Gymnasium environment; "
            f"supported kinds: {', '.join(SUPPORTED_KINDS)}"
        )
    eid = env_id(task)
    if eid in gymnasium.registry:
        del gymnasium.registry[eid]
    gymnasium.register(
        id=eid,
        entry_point=f"{__name__}:TaskEnv",
        kwargs={"task": task.name},
        max_episode_steps=task.episode_length,
        reward_threshold=task.reward_threshold,
    )
    return eid


def register_all() -> list[str]:
    """Register every registered task of a supported kind; skip the others. Returns the ids."""
    ids = []
    for name in _tasks.names():
        task = _tasks.make(name)
        if supports(task):
            ids.append(register_env(task))
    return ids
