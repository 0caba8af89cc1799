"""Gymnasium ids of the tasks: ``diffcontrol/<Name>-v0``, registered without JAX.

``gymnasium.make("diffcontrol/<Name>-v0")`` works right after ``import diffcontrol``, which
registers the built-in tasks' ids from ``BUILTIN``. The environments themselves
(``diffcontrol.envs``, which imports JAX) are imported by Gymnasium from the string entry
points only when one is made. ``diffcontrol.tasks.register`` registers every task it is given
from the task itself (``tasks.register_env``), the built-in ones again with the same specs: a
test keeps ``BUILTIN`` equal to them. This module imports nothing of the package: the tasks
use it, and the package's ``__init__`` registers ``BUILTIN`` with it.
"""

from __future__ import annotations

from typing import Any

NAMESPACE = "diffcontrol"
VERSION = 0
ENVS = "diffcontrol.envs"

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
    """The Gymnasium id of a task instance: ``diffcontrol/<Name>-v0``."""
    return f"{NAMESPACE}/{env_name(task)}-v{VERSION}"
