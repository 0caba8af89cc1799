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

from . import _registry
from ._version import __version__ as __version__
from .errors import ConfigError, DiffcontrolError

# The public names are imported when first used (PEP 562), so that `import diffcontrol` and
# `diffcontrol --help` do not import JAX, and so that this module imports none of the
# package's layers: it is the package's face, not a layer (type checkers read the names from
# __init__.pyi). The Gymnasium ids are registered at once (without JAX: the environments are
# imported when one is made).
_LAZY = {
    "check_task": ("checks", "check_task"),
    "ODETrainConfig": ("config", "ODETrainConfig"),
    "TrainConfig": ("config", "TrainConfig"),
    "MLPController": ("controllers", "MLPController"),
    "evaluate": ("evaluation", "evaluate"),
    "export": ("deploy", "export"),
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
    "load": ("runs", "load"),
    "list_tasks": ("tasks", "names"),
}

_registry.register_envs()  # gymnasium.make("diffcontrol/<Name>-v0") for every built-in task


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
    "export",
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
