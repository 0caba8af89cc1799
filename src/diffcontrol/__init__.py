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

from . import controllers, data, envs, rollout, systems, tasks, wrappers  # noqa: E402
from .checks import CheckReport, check_task  # noqa: E402
from .config import ODETrainConfig, TrainConfig  # noqa: E402
from .controllers import MLPController, straight_through_sign  # noqa: E402, F401
from .data import TrajectoryData, read_trajectories  # noqa: E402
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
from .io import AimingPolicy, NumpyPolicy, StatePolicy  # noqa: E402
from .recording import record  # noqa: E402
from .rollout import Trajectory  # noqa: E402
from .tasks import ContinuousTask, Task, make, register  # noqa: E402
from .training import TrainResult, resolve_config, train  # noqa: E402

envs.register_all()  # gymnasium.make("diffcontrol/<Name>-v0") for every registered task
wrappers.register()  # gymnasium.make("diffcontrol/PendulumFriction-v0", g=..., friction=...)


def load(run_dir: str | _os.PathLike) -> NumpyPolicy:
    """Load the controller saved by ``diffcontrol train`` in ``run_dir`` (or a ``model.json``).

    Returns a ``NumpyPolicy``: ``policy(obs)`` takes one Gymnasium observation (NumPy) and
    returns a valid Gymnasium action, so it drops into a plain ``gymnasium.make(...)`` loop.
    For an aiming task (the trebuchet) it returns an ``AimingPolicy``:
    ``policy(target_m, wind_mps) -> (angle_deg, weight_lb)``. For a continuous-time task (the
    swing-ups) a ``StatePolicy``: ``policy(state) -> force`` on the physical state
    ``(x, x_dot, theta, theta_dot)``, so any integrator can re-simulate the closed loop.

    Raises:
        ModelFileError: the file is missing, corrupt, or of an unsupported version.
    """
    from .io import AimingPolicy, StatePolicy, read_model

    doc = read_model(_Path(run_dir))
    if "features" in doc["observation"]:
        return StatePolicy(doc)
    known = doc["task"] in tasks.names()
    if known and tasks.make(doc["task"]).kind == "aiming":
        return AimingPolicy(doc)
    return NumpyPolicy(doc)


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
    "data",
    "envs",
    "evaluate",
    "evaluate_aiming",
    "list_tasks",
    "load",
    "make",
    "read_trajectories",
    "record",
    "register",
    "resolve_config",
    "rollout",
    "systems",
    "tasks",
    "train",
    "wrappers",
]
