"""Run directories: a trained controller saved with its settings, its evaluation and its
pictures, read back, and trained into, for any task (built-in, or the user's own).

A run directory holds ``run.json`` (the task, the settings and how the run was started,
written when training starts; ``"complete"`` once its files are written), ``checkpoint.npz``
(for resuming), ``model.json`` (the controller, runnable with NumPy alone), ``metrics.json``
(what was measured) and whatever pictures the task draws (``plots.write_figures``). A
planning controller (``plan_run``) is a run too, with its settings and model in ``model.json``.
"""

from .._run_files import (
    METRICS_FILE,
    MODEL_FILE,
    Run,
    mark_complete,
    read_run_file,
    release_claim,
    save_run,
)
from ._loop import LOOP_FILE, loop
from ._open import load, load_policy, open_run
from ._plan import plan_run
from ._sweep import SWEEP_FILE, stored_sweep, sweep_dir
from ._train import RunInterrupted, RunOutcome, describe, fitted_training, train_run
from ._use import aim_dir, animate_dir, evaluate_dir

__all__ = [
    "LOOP_FILE",
    "METRICS_FILE",
    "MODEL_FILE",
    "Run",
    "RunInterrupted",
    "RunOutcome",
    "SWEEP_FILE",
    "aim_dir",
    "animate_dir",
    "describe",
    "evaluate_dir",
    "fitted_training",
    "load",
    "loop",
    "mark_complete",
    "load_policy",
    "open_run",
    "plan_run",
    "read_run_file",
    "release_claim",
    "save_run",
    "stored_sweep",
    "sweep_dir",
    "train_run",
]
