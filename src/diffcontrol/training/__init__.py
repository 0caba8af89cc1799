"""Trainers: windowed BPTT through a task's simulator, on one shared driver."""

from ._bptt import Trainer, TrainState, make_optimizer, make_trainer
from ._driver import TrainingDiverged, TrainResult, resolve_config, task_params, train

__all__ = [
    "Trainer",
    "TrainState",
    "TrainResult",
    "TrainingDiverged",
    "make_optimizer",
    "make_trainer",
    "resolve_config",
    "task_params",
    "train",
]
