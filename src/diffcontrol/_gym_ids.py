"""Gymnasium ids of the tasks: ``diffcontrol/<Name>-v0``, registered without JAX.

``gymnasium.make("diffcontrol/<Name>-v0")`` works right after ``import diffcontrol``, which
registers the built-in tasks' ids from ``BUILTIN``. The environments themselves
(``diffcontrol.envs``, which imports JAX) are imported by Gymnasium from the string entry
points only when one is made. ``diffcontrol.tasks.register`` registers every task it is given
from the task itself (``register_env``), the built-in ones again with the same specs: a test
keeps ``BUILTIN`` equal to them.
"""

from __future__ import annotations

from typing import Any

NAMESPACE = "diffcontrol"
VERSION = 0
_ENVS = "diffcontrol.envs"

BUILTIN: tuple[tuple[str, str, str | None, int, float | None], ...] = (
    # (id, entry point, task, max_episode_steps, reward_threshold)
    ("diffcontrol/Pendulum-v0", "diffcontrol.envs:TaskEnv", "pendulum", 200, -200.0),
    ("diffcontrol/PendulumUnclipped-v0", "diffcontrol.envs:TaskEnv", "pendulum-unclipped", 1000,
     None),
    ("diffcontrol/CartPole-v0", "diffcontrol.envs:TaskEnv", "cartpole", 500, 475.0),
    ("diffcontrol/Acrobot-v0", "diffcontrol.envs:TaskEnv", "acrobot", 500, -100.0),
    ("diffcontrol/Trebuchet-v0", "diffcontrol.envs:TaskEnv", "trebuchet", 1, None),
    ("diffcontrol/CartPoleSwingUp-v0", "diffcontrol.envs:ContinuousTaskEnv", "cartpole-swingup",
     49, None),
    ("diffcontrol/CartPoleSwingUpLimited-v0", "diffcontrol.envs:ContinuousTaskEnv",
     "cartpole-swingup-limited", 49, None),
    ("diffcontrol/CartPoleSwingUpFriction-v0", "diffcontrol.envs:ContinuousTaskEnv",
     "cartpole-swingup-friction", 49, None),
    ("diffcontrol/MountainCarContinuous-v0", "diffcontrol.envs:TaskEnv",
     "mountain-car-continuous", 999, 90.0),
    ("diffcontrol/PendulumFriction-v0", "diffcontrol.wrappers:make_pendulum_friction", None, 200,
     None),
)  # fmt: skip


def register() -> None:
    """Register the ids of ``BUILTIN`` that are not registered yet."""
    from gymnasium.envs.registration import register, registry

    for env_id, entry_point, task, steps, threshold in BUILTIN:
        if env_id not in registry:
            register(
                id=env_id,
                entry_point=entry_point,
                kwargs={"task": task} if task else {},
                max_episode_steps=steps,
                reward_threshold=threshold,
            )


def env_name(task: Any) -> str:
    """The ``Name`` of ``diffcontrol/<Name>-v0`` for ``task`` (``task.env_name`` or derived)."""
    if getattr(task, "env_name", None):
        return str(task.env_name)
    return "".join(part.capitalize() for part in task.name.replace("_", "-").split("-"))


def env_id(task: Any) -> str:
    """The Gymnasium id of ``task`` (an instance or a registered name): ``diffcontrol/<Name>-v0``."""
    if isinstance(task, str):
        from . import tasks

        task = tasks.make(task)
    return f"{NAMESPACE}/{env_name(task)}-v{VERSION}"


def supports(task: Any) -> bool:
    """Whether ``task`` can be stepped as a Gymnasium environment by ``TaskEnv`` (every
    discrete-time task can)."""
    from .tasks._base import Task

    return isinstance(task, Task)


def _entry(task: Any) -> tuple[str, int] | None:
    """The environment class and the episode length (steps) for ``task``, if it has one."""
    from .tasks._base import ContinuousTask

    if supports(task):
        return f"{_ENVS}:TaskEnv", task.episode_length
    if isinstance(task, ContinuousTask):
        return f"{_ENVS}:ContinuousTaskEnv", task.default_config().saves - 1
    return None


def register_env(task: Any) -> str:
    """Register ``task`` as ``diffcontrol/<Name>-v0`` (again, if already there); returns the id.

    Raises:
        ConfigError: the task's kind cannot be a Gymnasium environment.
    """
    from gymnasium.envs.registration import register, registry

    entry = _entry(task)
    if entry is None:
        from .errors import ConfigError

        raise ConfigError(
            f"{task!r} is neither a Task nor a ContinuousTask, so it has no Gymnasium environment"
        )
    entry_point, steps = entry
    eid = env_id(task)
    if eid in registry:
        del registry[eid]
    register(
        id=eid,
        entry_point=entry_point,
        kwargs={"task": task.name},
        max_episode_steps=steps,
        reward_threshold=getattr(task, "reward_threshold", None),
    )
    return eid
