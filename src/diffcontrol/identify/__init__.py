"""Learning models of a system from recorded data.

- **Data** (``identify.data``): the trajectory table ``TrajectoryData`` and its CSV/NPZ
  files (``diffcontrol-trajectories``), every system's data (a single measured outcome is a
  one-step episode). ``record`` records any Gymnasium environment, as the real system of a
  task when ``task=`` is given (the columns are then the task's ``data_columns()``);
  ``record_data`` is a task's own recording (``record_task``).
- **Models**: the kinds of ``identify.kinds`` (``KINDS``, ``kind(name)``): ``params`` (grey
  box: the task's physical parameters), ``hybrid`` (the physics plus a ``Correction``
  network) and ``neural`` (a network alone), of a discrete step
  (``HybridModel``, ``NeuralModel``, ``model_task``; ``members=K`` makes the network an
  ``Ensemble`` of K, whose spread is the model's uncertainty) or of a vector field (the task's own
  model, ``identify.ode``).
- **Fitting**: ``fit(task, data, model, **settings) -> FitResult``, by the task's route
  (``model_route(task)``: its step, its vector field, or the task's own); the prediction
  errors of ``identify.steps`` / ``identify.ode`` and the plot of ``identify.plot``.
- **Files**: ``fit_dir`` writes a fit directory (``fitted.json`` by ``save_fit``,
  ``prediction.png``); ``read_fitted`` and ``fitted_model`` read it back, and
  ``real_system`` names the system its data came from (an environment id read from a file is
  used only where it needs no import).
(The record -> fit -> train loop that uses them is ``diffcontrol.runs.loop``.)
"""

from . import data
from ._fit import FitDir, fit, fit_dir, save_fit
from ._shooting import HORIZONS, FitResult
from .data import TrajectoryData, concat, read_trajectories
from .ensemble import Ensemble, mean_spread
from .fitted import (
    FITTED_FILE,
    FITTED_FORMAT,
    as_env,
    checked_env_id,
    fitted_model,
    fitted_physics,
    read_fitted,
    real_params,
    real_system,
)
from .hybrid import HybridModel, NeuralModel, model_task
from .kinds import KINDS, MIN_TRANSITIONS, MODEL_TYPES, NETWORK_MODELS, ModelKind, fit_model, kind
from .network import Correction, correction_from_dict, correction_to_dict
from .recording import describe, record, record_data, record_task
from .steps import fit_parameters, predict, prediction_errors

__all__ = [
    "FITTED_FILE",
    "FITTED_FORMAT",
    "HORIZONS",
    "MIN_TRANSITIONS",
    "MODEL_TYPES",
    "NETWORK_MODELS",
    "Correction",
    "Ensemble",
    "FitDir",
    "FitResult",
    "HybridModel",
    "KINDS",
    "ModelKind",
    "NeuralModel",
    "TrajectoryData",
    "as_env",
    "checked_env_id",
    "concat",
    "correction_from_dict",
    "correction_to_dict",
    "data",
    "fit",
    "fit_dir",
    "fit_model",
    "fit_parameters",
    "fitted_model",
    "fitted_physics",
    "kind",
    "mean_spread",
    "model_task",
    "predict",
    "prediction_errors",
    "read_fitted",
    "read_trajectories",
    "real_params",
    "real_system",
    "record",
    "record_data",
    "record_task",
    "describe",
    "save_fit",
]
