"""diffcontrol: train controllers by differentiating through simulators.

The public API::

    import diffcontrol
    task = diffcontrol.make("pendulum")              # a registered task
    result = diffcontrol.train(task)                 # BPTT through its simulator
    policy = diffcontrol.load("runs/pendulum")       # obs (NumPy) -> Gymnasium action
"""

from __future__ import annotations

import os as _os
from pathlib import Path as _Path

__version__ = "0.1.0"

from . import controllers, envs, identify, rollout, runs, systems, tasks, wrappers  # noqa: E402
from .checks import CheckReport, check_task  # noqa: E402
from .config import ODETrainConfig, TrainConfig  # noqa: E402
from .controllers import MLPController, straight_through_sign  # noqa: E402, F401
from .errors import (  # noqa: E402
    ConfigError,
    DataFileError,
    DiffcontrolError,
    InsufficientDataError,
    ModelFileError,
    RunDirectoryError,
    SolverFailed,
    TaskCheckError,
    TrainingDiverged,
    UnknownTaskError,
)
from .evaluation import AimResult, EvalResult, evaluate, evaluate_aiming  # noqa: E402
from .identify import FitResult, TrajectoryData, fit, read_trajectories, record  # noqa: E402
from .io import AimingPolicy, NumpyPolicy, StatePolicy  # noqa: E402
from .rollout import Trajectory  # noqa: E402
from .runs import Run, open_run  # noqa: E402
from .tasks import ContinuousTask, Task, make, register, resolve  # noqa: E402
from .training import TrainResult, resolve_config, train  # noqa: E402

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
    from .io import read_model

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
    return tasks.names()


__all__ = [
    "AimResult",
    "AimingPolicy",
    "CheckReport",
    "ConfigError",
    "ContinuousTask",
    "DataFileError",
    "DiffcontrolError",
    "EvalResult",
    "InsufficientDataError",
    "MLPController",
    "ModelFileError",
    "NumpyPolicy",
    "ODETrainConfig",
    "RunDirectoryError",
    "SolverFailed",
    "StatePolicy",
    "Task",
    "TaskCheckError",
    "TrainConfig",
    "TrainResult",
    "Trajectory",
    "TrainingDiverged",
    "TrajectoryData",
    "UnknownTaskError",
    "check_task",
    "controllers",
    "envs",
    "evaluate",
    "evaluate_aiming",
    "fit",
    "FitResult",
    "identify",
    "list_tasks",
    "load",
    "make",
    "read_trajectories",
    "record",
    "register",
    "resolve_config",
    "rollout",
    "runs",
    "Run",
    "open_run",
    "resolve",
    "systems",
    "tasks",
    "train",
    "wrappers",
]
