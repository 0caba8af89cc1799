"""Trainers: windowed BPTT through a discrete-time simulator, and differentiation through an
ODE solve for continuous-time tasks, on one shared driver; sweeps of whole runs as one
vmapped program."""

from ..errors import SolverFailed, TrainingDiverged
from ._bptt import Trainer, TrainState, make_optimizer, make_trainer
from ._driver import TrainResult, resolve_config, task_params, train
from ._ode import ODETrainer, ODETrainState, make_ode_trainer
from ._programs import clear_compiled
from ._sweep import SweepResult, grid, sweep

__all__ = [
    "ODETrainer",
    "ODETrainState",
    "SolverFailed",
    "SweepResult",
    "make_ode_trainer",
    "Trainer",
    "TrainState",
    "TrainResult",
    "TrainingDiverged",
    "clear_compiled",
    "grid",
    "make_optimizer",
    "make_trainer",
    "resolve_config",
    "sweep",
    "task_params",
    "train",
]
