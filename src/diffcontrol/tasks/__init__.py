"""Tasks: a system plus its losses, initial-state distribution and horizon, in a registry.

``make("pendulum")`` and the CLI share the registry, so a task registered from user code with
``register`` is trainable from Python exactly like the built-in ones. The built-in tasks are
rows of one table (``diffcontrol._registry``), each made (its module imported) when first
named. ``resolve`` also finds a user's task by import path (``"my_tasks:Acrobot"``) or by the
name an installed package gives it in the ``diffcontrol.tasks`` entry-point group.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import sys
from typing import Any

from .. import _registry
from .._registry import BUILTIN, ENTRY_POINT_GROUP
from ..errors import ConfigError, UnknownTaskError
from ._base import (
    ContinuousTask,
    StepLoss,
    Task,
    TrajectoryLoss,
    check_params,
    controller_kwargs,
    task_params,
)
from ._stroke import Stroke

AnyTask = Task | ContinuousTask
_REGISTRY: dict[str, AnyTask] = {}
"""The tasks made or registered in this process, by name."""


def supports_env(task: Any) -> bool:
    """Whether ``task`` can be stepped as a Gymnasium environment by ``envs.TaskEnv`` (every
    discrete-time task can)."""
    return isinstance(task, Task)


def env_entry(task: Any) -> tuple[str, int] | None:
    """The environment class and the episode length (steps) for ``task``, if it has one."""
    if supports_env(task):
        return f"{_registry.ENVS}:TaskEnv", task.episode_length
    if isinstance(task, ContinuousTask):
        return f"{_registry.ENVS}:ContinuousTaskEnv", task.default_config().saves - 1
    return None


def register_env(task: Any) -> str:
    """Register ``task`` as ``diffcontrol/<Name>-v0`` (again, if already there); returns the id.

    Raises:
        ConfigError: the task's kind cannot be a Gymnasium environment.
    """
    from gymnasium.envs.registration import register as register_gym
    from gymnasium.envs.registration import registry

    entry = env_entry(task)
    if entry is None:
        raise ConfigError(
            f"{task!r} is neither a Task nor a ContinuousTask, so it has no Gymnasium environment"
        )
    entry_point, steps = entry
    eid = _registry.env_id(task)
    if eid in registry:
        del registry[eid]
    register_gym(
        id=eid,
        entry_point=entry_point,
        kwargs={"task": task.name},
        max_episode_steps=steps,
        reward_threshold=getattr(task, "reward_threshold", None),
    )
    return eid


def as_task(task: Any, where: str) -> AnyTask:
    """``task`` itself when it is a task, the task it names when it is a string
    (``resolve``); anything else is refused in one line that says what ``where`` takes.

    Raises:
        ConfigError: neither a task nor a name; UnknownTaskError: a name of no task.
    """
    if isinstance(task, Task | ContinuousTask):
        return task
    if isinstance(task, str):
        return resolve(task)
    raise ConfigError(
        f"{where} takes a task (diffcontrol.make('pendulum'), or an instance of your Task) or "
        f"its name, not {task!r} ({type(task).__name__})"
    )


def register(task: AnyTask) -> AnyTask:
    """Add a task instance to the registry under ``task.name`` and make it a Gymnasium
    environment (``diffcontrol/<Name>-v0``) at once; returns it.

    Raises:
        ValueError: a task of another class is registered under the same name (a built-in
            task's name included).
        ConfigError: ``task`` is not a task instance.
    """
    if not isinstance(task, Task | ContinuousTask):
        raise ConfigError(
            f"register() takes an instance of a Task or ContinuousTask subclass, not {task!r} "
            f"({type(task).__name__})"
        )
    row = _registry.builtin(task.name)
    own = f"{type(task).__module__}:{type(task).__qualname__}"
    other = type(_REGISTRY[task.name]) if task.name in _REGISTRY else None
    if (other is not None and other is not type(task)) or (row and row.path != own):
        raise ValueError(f"a different task is already registered as {task.name!r}")
    _REGISTRY[task.name] = task
    if env_entry(task) is not None:
        register_env(task)
    return task


def make(name: str) -> AnyTask:
    """The registered task called ``name``.

    Raises:
        UnknownTaskError: no task has that name (the message lists those that do).
    """
    _check_name(name)
    if name in _REGISTRY:
        return _REGISTRY[name]
    row = _registry.builtin(name)
    if row is None:
        raise UnknownTaskError(
            f"unknown task {name!r}; choose one of: {', '.join(sorted(names()))} "
            "(`diffcontrol list` describes them)"
        )
    return register(_builtin_class(row)())


def _check_name(name: Any) -> None:
    if not isinstance(name, str):
        raise ConfigError(
            "diffcontrol.make() takes a task's name, e.g. 'pendulum', or an import path "
            f"'module:Class', not {name!r} ({type(name).__name__})"
        )


def _builtin_class(row: _registry.Builtin) -> type:
    """The class of a built-in task: the registry's lazy lookup of its module."""
    module, _, cls = row.path.partition(":")
    return getattr(importlib.import_module(module), cls)


def resolve(spec: str) -> AnyTask:
    """The task ``spec`` names, registered on the way: a registered name, the name of an
    entry point in ``ENTRY_POINT_GROUP``, or an import path ``module:attribute`` (a ``Task``
    or ``ContinuousTask`` subclass, which is instantiated, or an instance). The current
    directory is searched for the module, as ``python -m`` would.

    Only call this with what a user named (a command-line argument, code): diffcontrol never
    imports a module because a file names it.

    Raises:
        UnknownTaskError: nothing of that name, or the module does not import, or the
            attribute is not a task.
    """
    _check_name(spec)
    if spec in _REGISTRY or _registry.builtin(spec):
        return make(spec)
    target = spec
    if ":" not in spec:
        found = [
            ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name == spec
        ]
        if not found:
            make(spec)  # raises, listing the registered names
        target = found[0].value
    module_name, _, attribute = target.partition(":")
    if not module_name or not attribute:
        raise UnknownTaskError(f"task {spec!r}: expected module:Class, e.g. my_tasks:Acrobot")
    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except Exception as e:  # noqa: BLE001 - any failure of the user's module is reported
        raise UnknownTaskError(
            f"task {spec!r}: cannot import {module_name!r} ({type(e).__name__}: {e}); check "
            "the module path (run from the directory that holds it, or install its package)"
        ) from None
    obj = module
    for part in attribute.split("."):
        if not hasattr(obj, part):
            raise UnknownTaskError(f"task {spec!r}: module {module_name!r} has no {attribute!r}")
        obj = getattr(obj, part)
    if isinstance(obj, type) and issubclass(obj, Task | ContinuousTask):
        try:
            obj = obj()
        except TypeError as e:
            raise UnknownTaskError(
                f"task {spec!r}: {attribute} cannot be created ({e}); implement its abstract "
                "methods or give its __init__ defaults"
            ) from None
    if not isinstance(obj, Task | ContinuousTask):
        raise UnknownTaskError(
            f"task {spec!r}: {attribute} is a {type(obj).__name__}, not a diffcontrol Task or "
            "ContinuousTask (subclass or instance)"
        )
    obj.source = target
    if obj.name in _REGISTRY and _REGISTRY[obj.name] is not obj:
        if type(_REGISTRY[obj.name]) is type(obj):
            return _REGISTRY[obj.name]
        raise UnknownTaskError(
            f"task {spec!r} is named {obj.name!r}, which a different registered task already "
            "uses; give it another name"
        )
    return register(obj)


def named_by_file(name: object, where: str, fix: str) -> AnyTask:
    """The task a file names (a run's ``run.json`` or ``model.json``, a sweep's
    ``sweep.json``, ...): a registered task or the name of an installed entry point, and
    nothing else. This is the one way a task read from a file is found: diffcontrol never
    imports a module because a file names it, so an import path read from a file is refused
    and the user names it again on the command line (or in Python).

    Args:
        name: the task as the file gives it.
        where: the file, for the message.
        fix: how to name the task instead, for the message (a shell-quoted command).

    Raises:
        UnknownTaskError: one line naming the file, the task and ``fix``.
    """
    if isinstance(name, str) and name and ":" not in name:
        if name in _REGISTRY or _registry.builtin(name):  # a built-in one is made on demand
            return make(name)
        if any(ep.name == name for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)):
            return resolve(name)
    raise UnknownTaskError(
        f"{where} names the task {name!r}, which is not registered; name it: {fix} "
        "(diffcontrol never imports code because a file names it)"
    )


def names() -> list[str]:
    """Names of the tasks: the built-in ones in the table's order, then those registered in
    this process, in registration order."""
    builtin = [row.name for row in BUILTIN]
    return builtin + [name for name in _REGISTRY if name not in builtin]


# The built-in tasks' classes by name (``diffcontrol.tasks.Pendulum``, ...), from their modules
# when first used, as the registry makes them.
_CLASSES = {row.path.partition(":")[2]: row.path.partition(":")[0] for row in BUILTIN}


def __getattr__(name: str) -> Any:
    if name not in _CLASSES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(_CLASSES[name]), name)


__all__ = [
    "AnyTask",
    "Task",
    "ContinuousTask",
    "StepLoss",
    "TrajectoryLoss",
    "make",
    "names",
    "named_by_file",
    "register",
    "as_task",
    "register_env",
    "env_entry",
    "supports_env",
    "resolve",
    "task_params",
    "check_params",
    "controller_kwargs",
    "Stroke",
    "ENTRY_POINT_GROUP",
    "Pendulum",
    "PendulumUnclipped",
    "CartPole",
    "MountainCarContinuous",
    "Acrobot",
]
