"""A task's Gymnasium twin: its spaces, its actions, its environment and its states.

Each function here is what the layers do with a task and the outside world, with the default
body in this module; a task changes one by defining a method of the same name (a user's task
in one file), or a built-in system by registering for its class (``tasks._hooks``). The
defaults suit a task whose observations and actions are vectors of its sizes and whose twin is
a classic-control environment of Gymnasium.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import equinox as eqx
import numpy as np
from jaxtyping import Array, PyTree

from ._registry import env_id as own_env_id
from .tasks import Task
from .tasks._hooks import task_hook


@task_hook
def observation_space(task: Any) -> Any:
    """The Gymnasium observation space of the task's environment (default: an unbounded
    ``Box`` of ``observation_size``)."""
    from gymnasium import spaces

    return spaces.Box(-np.inf, np.inf, (task.observation_size,), dtype=np.float32)


@task_hook
def action_space(task: Any) -> Any:
    """The Gymnasium action space: ``Discrete(2)`` for a ``sign`` head (0 pushes towards -1),
    ``Discrete(action_size)`` for an ``argmax`` head, else a ``Box`` in the head's bounds."""
    from gymnasium import spaces

    if task.action_head == "sign":
        return spaces.Discrete(2)
    if task.action_head == "argmax":
        return spaces.Discrete(task.action_size)
    if task.action_low is not None and task.action_high is not None:
        low, high = (np.asarray(b, np.float32) for b in (task.action_low, task.action_high))
        return spaces.Box(low, high, dtype=np.float32)
    return spaces.Box(-np.inf, np.inf, (task.action_size,), dtype=np.float32)


@task_hook
def gym_action(task: Any, action: np.ndarray) -> Any:
    """A controller's output as a valid action of the task's environment (default: as
    float32)."""
    return np.asarray(action, dtype=np.float32)


@task_hook
def action_from_gym(task: Any, action: Any) -> np.ndarray:
    """The task's action vector for an action of ``action_space``: ``Discrete(2)`` 0/1 ->
    ``[-1]``/``[+1]``, ``Discrete(n)`` i -> one-hot, a ``Box`` action clipped."""
    if task.action_head == "sign":
        return np.array([1.0 if int(action) == 1 else -1.0])
    if task.action_head == "argmax":
        return np.eye(task.action_size)[int(action)]
    a = np.asarray(action, np.float64).reshape(task.action_size)
    if task.action_low is not None and task.action_high is not None:
        a = np.clip(a, task.action_low, task.action_high)
    return a


@task_hook
def make_gym_env(task: Any, **kwargs: Any) -> Any:
    """``gymnasium.make(gym_id, **kwargs)``, or of the task's own environment
    ``diffcontrol/<Name>-v0`` where it has no Gymnasium twin."""
    import gymnasium

    return gymnasium.make(task.gym_id or own_env_id(task), **kwargs)


@task_hook
def set_gym_state(task: Any, env: Any, state: np.ndarray) -> None:
    """Put the Gymnasium twin ``env`` (from ``make_gym_env``, after ``env.reset()``) into
    the task's ``state`` (NumPy, shape as ``reset`` returns).

    ``diffcontrol.check_task`` compares ``step`` with the twin's ``env.step`` from the same
    state. The default suits Gymnasium's classic-control environments, whose state is the
    float64 array ``env.unwrapped.state``, laid out as the task's; a task whose twin keeps its
    state elsewhere, or in another layout (MuJoCo's ``set_state(qpos, qvel)``), says how.
    """
    env.unwrapped.state = np.asarray(state, np.float64)


@task_hook
def gym_state(task: Any, env: Any) -> np.ndarray:
    """The task's state of the Gymnasium twin ``env`` (float64, laid out as ``reset``'s), for
    recordings: the classic-control twins' ``env.unwrapped.state`` by default."""
    return np.array(env.unwrapped.state, dtype=np.float64)


@task_hook
def gym_label(task: Any) -> str:
    """How evaluation results name the environment: ``gym_id``, or the task's own
    ``diffcontrol/<Name>-v0``."""
    return task.gym_id or own_env_id(task)


@task_hook
def state_from_observation(task: Any, observation: Array) -> Array:
    """The state that ``observe`` maps to ``observation`` (the inverse of ``observe``), so that
    a model can be fitted to recorded observations and a planner can act on them.

    Raises:
        NotImplementedError: the task cannot reconstruct its state (the default).
    """
    raise NotImplementedError(f"task {task.name!r} cannot reconstruct a state")


def knows_state(task: Any) -> bool:
    """Whether the task reconstructs states from observations (``state_from_observation``)."""
    return state_from_observation.implementation(task) is not state_from_observation.dispatch(
        object
    )


@task_hook
def params_of_env(task: Any, env_id: str, env_kwargs: dict | None = None) -> PyTree | None:
    """The physical parameters of a Gymnasium environment that is this task's system with
    other physics, or ``None`` where it is not (or they are unknown): what grid methods (the
    reference optimum of ``evaluate --optimum``) solve when a controller is judged on another
    system than the task's own.

    Default: for a discrete-time task's ``gym_id`` or one of its ``data_env_ids`` whose
    keyword arguments all name fields of ``default_params()`` with numbers (e.g.
    ``diffcontrol/PendulumFriction-v0`` with ``g=12, friction=0.1``), the default parameters
    with those values; ``None`` for any other environment or argument (``render_mode``, an
    option of the environment that is not a parameter).
    """
    if not isinstance(task, Task) or env_id not in (
        task.gym_id,
        *getattr(task, "data_env_ids", ()),
    ):
        return None
    params = task.default_params()
    kwargs = dict(env_kwargs or {})
    known = {f.name for f in dataclasses.fields(params)}
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in kwargs.values())
    if not set(kwargs) <= known or not numbers:
        return None
    names = sorted(kwargs)
    return eqx.tree_at(
        lambda p: tuple(getattr(p, n) for n in names),
        params,
        tuple(float(kwargs[n]) for n in names),
    )
