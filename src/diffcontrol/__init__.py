"""diffcontrol: train controllers by differentiating through simulators.

The public API, about twenty names (everything else lives in its module: ``diffcontrol.tasks``,
``diffcontrol.identify``, ``diffcontrol.errors``, ...)::

    import diffcontrol
    task = diffcontrol.make("pendulum")              # a task, or "my_module:MyTask"
    result = diffcontrol.train(task)                 # BPTT through its simulator
    result.save("runs/pendulum")                     # model.json, metrics, pictures
    policy = diffcontrol.load("runs/pendulum")       # obs (NumPy) -> Gymnasium action
    diffcontrol.evaluate(policy, task)               # in Gymnasium's own environment
    diffcontrol.fit(task, data, model="hybrid")      # learn the model from recorded data
"""

from __future__ import annotations

import importlib as _importlib
import importlib.util as _importlib_util
import os as _os
from pathlib import Path as _Path
from typing import TYPE_CHECKING

from . import _gym_ids
from .errors import ConfigError, DiffcontrolError

__version__ = "0.1.0"

# The public names are imported when first used (PEP 562), so that `import diffcontrol` and
# `diffcontrol --help` do not import JAX. The Gymnasium ids are registered at once (without
# JAX: the environments are imported when one is made).
_LAZY = {
    "check_task": ("checks", "check_task"),
    "ODETrainConfig": ("config", "ODETrainConfig"),
    "TrainConfig": ("config", "TrainConfig"),
    "MLPController": ("controllers", "MLPController"),
    "evaluate": ("evaluation", "evaluate"),
    "fit": ("identify", "fit"),
    "record": ("identify", "record"),
    "Run": ("runs", "Run"),
    "open_run": ("runs", "open_run"),
    "ContinuousTask": ("tasks", "ContinuousTask"),
    "Task": ("tasks", "Task"),
    "register": ("tasks", "register"),
    "make": ("tasks", "resolve"),
    "TrainResult": ("training", "TrainResult"),
    "sweep": ("training", "sweep"),
    "train": ("training", "train"),
}

if TYPE_CHECKING:
    from .checks import check_task
    from .config import ODETrainConfig, TrainConfig
    from .controllers import MLPController
    from .evaluation import evaluate
    from .identify import fit, record
    from .runs import Run, open_run
    from .tasks import ContinuousTask, Task, register
    from .tasks import resolve as make
    from .training import TrainResult, train

_gym_ids.register()  # gymnasium.make("diffcontrol/<Name>-v0") for every built-in task


def __getattr__(name: str):
    if name in _LAZY:
        module, attribute = _LAZY[name]
        value = getattr(_importlib.import_module(f".{module}", __name__), attribute)
    elif not name.startswith("_") and _importlib_util.find_spec(f"{__name__}.{name}"):
        value = _importlib.import_module(f".{name}", __name__)  # diffcontrol.envs, ...
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})


def load(run_dir: str | _os.PathLike, task: Task | ContinuousTask | str | None = None):
    """Load the controller saved in ``run_dir`` (a run directory or its ``model.json``) as a
    NumPy policy, for any task.

    The policy is the task's (its ``load_policy`` hook): by default a ``NumpyPolicy``,
    ``policy(obs)`` -> a valid Gymnasium action, which drops into a plain
    ``gymnasium.make(...)`` loop; an ``AimingPolicy`` for the trebuchet
    (``policy(target_m, wind_mps) -> (angle_deg, weight_lb)``); a ``StatePolicy`` for a
    continuous-time task (``policy(state) -> action`` on the physical state). A planner
    (written by ``diffcontrol plan``) loads as an ``mpc.PlannerPolicy``, ``policy(obs)`` ->
    Gymnasium action like the others, but it imports JAX and runs one compiled solve per
    call (its terminal value grid, if any, is solved again here from the stored settings);
    a continuous-time task's planner as an ``mpc.SampledPlannerPolicy``, ``policy(state)`` ->
    action like a ``StatePolicy``, but an action to hold for ``policy.dt`` seconds (one
    solve per control period, JAX again).

    Args:
        run_dir: a directory written by ``diffcontrol train`` or ``result.save``.
        task: the task (or its name or import path) when it is not registered; without it a
            task that is not registered loads by the file's format alone (a ``NumpyPolicy``,
            or a ``StatePolicy`` where the file gives the state's features).

    Raises:
        ModelFileError: the file is missing, corrupt, or of an unsupported version.
    """
    from . import io, tasks
    from .errors import ModelFileError
    from .io import NumpyPolicy, StatePolicy, read_model

    doc = read_model(_Path(run_dir))
    if isinstance(task, str):
        task = tasks.resolve(task)
    if task is None and doc["task"] in tasks.names():
        task = tasks.make(doc["task"])
    if task is not None:
        from .runs import load_policy

        return load_policy(task, doc)  # the task's, or a planner's
    if io.is_planner(doc):
        raise ModelFileError(f"the planner's task {doc['task']!r} is not registered; pass task=")
    return StatePolicy(doc) if "features" in doc["observation"] else NumpyPolicy(doc)


def list_tasks() -> list[str]:
    """Names of the registered tasks."""
    from . import tasks

    return tasks.names()


__all__ = [
    "ConfigError",
    "ContinuousTask",
    "DiffcontrolError",
    "MLPController",
    "ODETrainConfig",
    "Run",
    "Task",
    "TrainConfig",
    "TrainResult",
    "check_task",
    "evaluate",
    "fit",
    "list_tasks",
    "load",
    "make",
    "open_run",
    "record",
    "register",
    "sweep",
    "train",
]
