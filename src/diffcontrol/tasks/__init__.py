"""Tasks: a system plus its losses, initial-state distribution and horizon, in a registry.

``make("pendulum")`` and the CLI share the registry, so a task registered from user code with
``register`` is trainable from Python exactly like the built-in ones.
"""

from __future__ import annotations

from ..errors import UnknownTaskError
from ._base import ContinuousTask, StepLoss, Task, TrajectoryLoss
from .acrobot import Acrobot
from .cartpole import CartPole
from .pendulum import Pendulum, PendulumUnclipped
from .swingup import (
    CartPoleSwingUp,
    CartPoleSwingUpFriction,
    CartPoleSwingUpLimited,
    SwingUpTrajectory,
)
from .trebuchet import TrebuchetAiming

AnyTask = Task | ContinuousTask
_REGISTRY: dict[str, AnyTask] = {}


def register(task: AnyTask) -> AnyTask:
    """Add a task instance to the registry under ``task.name``; returns it."""
    if task.name in _REGISTRY and type(_REGISTRY[task.name]) is not type(task):
        raise ValueError(f"a different task is already registered as {task.name!r}")
    _REGISTRY[task.name] = task
    return task


def make(name: str) -> AnyTask:
    """The registered task called ``name``.

    Raises:
        UnknownTaskError: no task has that name (the message lists those that do).
    """
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownTaskError(
            f"unknown task {name!r}; choose one of: {', '.join(sorted(_REGISTRY))} "
            "(`diffcontrol list` describes them)"
        ) from None


def names() -> list[str]:
    """Names of the registered tasks, in registration order."""
    return list(_REGISTRY)


for _task in (
    Pendulum(),
    PendulumUnclipped(),
    CartPole(),
    Acrobot(),
    TrebuchetAiming(),
    CartPoleSwingUp(),
    CartPoleSwingUpLimited(),
    CartPoleSwingUpFriction(),
):
    register(_task)

__all__ = [
    "AnyTask",
    "Task",
    "ContinuousTask",
    "StepLoss",
    "TrajectoryLoss",
    "SwingUpTrajectory",
    "CartPoleSwingUp",
    "CartPoleSwingUpLimited",
    "CartPoleSwingUpFriction",
    "make",
    "names",
    "register",
    "Pendulum",
    "PendulumUnclipped",
    "CartPole",
    "Acrobot",
    "TrebuchetAiming",
]
