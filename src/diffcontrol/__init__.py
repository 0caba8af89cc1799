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

import os as _os
from pathlib import Path as _Path

__version__ = "0.1.0"

from . import envs, wrappers  # noqa: E402
from .checks import check_task  # noqa: E402
from .config import ODETrainConfig, TrainConfig  # noqa: E402
from .controllers import MLPController  # noqa: E402
from .errors import ConfigError, DiffcontrolError  # noqa: E402
from .evaluation import evaluate  # noqa: E402
from .identify import fit, record  # noqa: E402
from .runs import Run, open_run  # noqa: E402
from .tasks import ContinuousTask, Task, register  # noqa: E402
from .tasks import resolve as make  # noqa: E402
from .training import TrainResult, sweep, train  # noqa: E402

envs.register_all()  # gymnasium.make("diffcontrol/<Name>-v0") for every registered task
wrappers.register()  # gymnasium.make("diffcontrol/PendulumFriction-v0", g=..., friction=...)


def load(run_dir: str | _os.PathLike, task: Task | ContinuousTask | str | None = None):
    """Load the controller saved in ``run_dir`` (a run directory or its ``model.json``) as a
    NumPy policy, for any task.

    The policy is the task's (its ``load_policy`` hook): by default a ``NumpyPolicy``,
    ``policy(obs)`` -> a valid Gymnasium action, which drops into a plain
    ``gymnasium.make(...)`` loop; an ``AimingPolicy`` for the trebuchet
    (``policy(target_m, wind_mps) -> (angle_deg, weight_lb)``); a ``StatePolicy`` for a
    continuous-time task (``policy(state) -> action`` on the physical state).

    Args:
        run_dir: a directory written by ``diffcontrol train`` or ``result.save``.
        task: the task (or its name or import path) when it is not registered; without it a
            task that is not registered loads by the file's format alone (a ``NumpyPolicy``,
            or a ``StatePolicy`` where the file gives the state's features).

    Raises:
        ModelFileError: the file is missing, corrupt, or of an unsupported version.
    """
    from . import tasks
    from .io import NumpyPolicy, StatePolicy, read_model

    doc = read_model(_Path(run_dir))
    if isinstance(task, str):
        task = tasks.resolve(task)
    if task is None and doc["task"] in tasks.names():
        task = tasks.make(doc["task"])
    if task is not None:
        return task.load_policy(doc)
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
