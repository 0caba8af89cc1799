"""Errors raised for user mistakes.

Every error a user can cause is caught at the boundary (CLI, config, file loading) and raised
as one of these, with a message that names the bad value and says what to do. The CLI prints
the message on one line and exits with status 2.
"""

from __future__ import annotations


class DiffcontrolError(ValueError):
    """Base class of every user-facing error of diffcontrol."""


class ConfigError(DiffcontrolError):
    """A training or evaluation setting is out of range (for example ``window <= 0``)."""


class TaskCheckError(ConfigError):
    """A task that breaks the contract the trainers rely on (``diffcontrol.check_task``):
    a method that returns the wrong shape or dtype, a non-finite or non-deterministic output,
    or a step that disagrees with the task's Gymnasium twin. The message is one line that
    names the method and what it returned."""


class UnknownTaskError(DiffcontrolError, KeyError):
    """A task name that is not registered."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


class ModelFileError(DiffcontrolError):
    """A ``model.json`` (or checkpoint) that is missing, corrupt or of an unknown version."""


class RunDirectoryError(DiffcontrolError):
    """An output directory that cannot be written or already holds a different run."""


class TrainingDiverged(DiffcontrolError):
    """The loss or the weights became non-finite; the last good checkpoint is kept."""


class SolverFailed(TrainingDiverged):
    """Every population member's ODE solve failed (or its loss became non-finite)."""


class DataFileError(DiffcontrolError):
    """A trajectory data file (CSV or NPZ) that is missing, malformed or inconsistent."""


class InsufficientDataError(DiffcontrolError):
    """Too little recorded data for the model asked for (the message says how much is needed)."""


class TrainingWarning(UserWarning):
    """A training run that finished but likely did not do what was meant: a loss that does
    not depend on the controller, a loss that never moves, or ``keep_best`` returning the
    untrained controller. Also listed in ``TrainResult.metrics["warnings"]``."""


class Interrupted(KeyboardInterrupt):
    """A long command (a training run, a comparison) was interrupted (Ctrl-C); the message
    says what was kept and the command that continues it. The CLI prints it and exits 130."""
