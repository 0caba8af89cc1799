"""``fitted.json``: the one fitted-model file (format ``diffcontrol-fitted-model``, version 1).

Written by ``save_fit`` (``diffcontrol fit``), read back by ``read_fitted`` for ``diffcontrol
train --model``: ``fitted_physics`` / ``fitted_model`` rebuild the model, and ``real_system`` /
``as_env`` / ``real_params`` give the system the model's data came from, where a controller
trained through the model is judged. An environment id read from a file is only used where it
needs no import (``checked_env_id``): diffcontrol never imports a module because a file names it.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from .. import _gym
from ..errors import ConfigError, ModelFileError
from ..io import read_json, scalar_arguments
from ..tasks import Task, check_params
from ..tasks._hooks import task_hook
from .hybrid import HybridModel, NeuralModel, model_task
from .kinds import KINDS, kind

FITTED_FILE = "fitted.json"
FITTED_FORMAT = "diffcontrol-fitted-model"


def read_fitted(path: str | os.PathLike) -> dict[str, Any]:
    """Read and check a ``fitted.json`` (or the directory holding one).

    Raises:
        ModelFileError: the file is missing, not a fitted model, or malformed (says which).
    """
    path = Path(path)
    if path.is_dir():
        path = path / FITTED_FILE
    if not path.exists():
        raise ModelFileError(
            f"no fitted model at {path}; make one with `diffcontrol fit TASK --data FILE "
            "--model {params,hybrid,neural} --out DIR`"
        )
    doc = read_json(path, "fitted model")
    if not isinstance(doc, dict) or doc.get("format") != FITTED_FORMAT:
        raise ModelFileError(f"{path} is not a {FITTED_FORMAT} file (written by `diffcontrol fit`)")
    if doc.get("version") != 1:
        raise ModelFileError(f"{path} has version {doc.get('version')!r}; this diffcontrol reads 1")
    model_type = doc.get("model")
    if not isinstance(model_type, str) or model_type not in KINDS:
        raise ModelFileError(f"{path}: unknown model kind {model_type!r}")
    values = doc.get("all_parameters")
    if not isinstance(values, dict) or not all(
        isinstance(v, int | float) and math.isfinite(v) for v in values.values()
    ):
        raise ModelFileError(f"{path}: 'all_parameters' must map names to finite numbers")
    if kind(model_type).network and not isinstance(doc.get("network"), dict):
        raise ModelFileError(f"{path}: a {model_type} model needs its 'network'")
    doc["_path"] = str(path)
    return doc


def fitted_physics(task: Any, doc: dict[str, Any]) -> Any:
    """The task's parameters with the fitted file's ``all_parameters``.

    Raises:
        ModelFileError: the file is for another task or names a parameter the task lacks.
    """
    where = doc.get("_path", "the fitted model")
    if doc.get("task") != task.name:
        raise ModelFileError(
            f"{where} was fitted for task {doc.get('task')!r}, not {task.name!r}; train "
            f"{doc.get('task')} with it, or fit {task.name}"
        )
    params = task.default_params()
    known = {f.name for f in dataclasses.fields(params)}
    unknown = sorted(set(doc["all_parameters"]) - known)
    if unknown:
        raise ModelFileError(f"{where}: task {task.name!r} has no parameter(s) {unknown}")
    names = sorted(doc["all_parameters"])
    return eqx.tree_at(
        lambda p: tuple(getattr(p, n) for n in names),
        params,
        tuple(float(doc["all_parameters"][n]) for n in names),
    )


def fitted_model(task: Any, doc: dict[str, Any]) -> HybridModel | NeuralModel | Any:
    """The model of a fitted file: the physical parameters (``params``), or a ``HybridModel``
    / ``NeuralModel`` whose correction is one network or an ``Ensemble`` (use
    ``model_task(task, model)`` to train or predict with it).

    Raises:
        ModelFileError: a malformed network or ensemble (one line naming it)."""
    physics = fitted_physics(task, doc)
    model_kind = kind(doc["model"])
    sizes = network_sizes(task) if model_kind.network else None
    return model_kind.load(doc, physics, sizes, doc.get("_path", "the fitted model"))


def network_sizes(task: Any) -> tuple[int, int]:
    """The inputs (observation and action) and outputs (the state) of the network of a
    discrete-time task's hybrid or neural model."""
    obs = jax.ShapeDtypeStruct((task.observation_size,), jnp.float32)
    state = jax.eval_shape(_gym.state_from_observation.bound(task), obs)
    return task.observation_size + task.action_size, int(state.shape[0])


def real_system(doc: dict, trusted: str | None = None, task: Any = None) -> dict | None:
    """The system a fitted model's data came from: ``{"env_id", "env_kwargs"}`` for data
    recorded from a Gymnasium environment, ``{"params"}`` (the physical parameters of a
    simulated system, from the data's metadata), or None. ``trusted``: an id the user named
    (``--env``), which may be imported; it must be the data's own.

    Raises:
        ModelFileError: ``data`` (or its metadata) is not a JSON object.
        ConfigError: an environment id or arguments that are not usable (``checked_env``),
            or physics ``task`` (where given) has no meaning for (``check_real_env``).
    """
    where = doc.get("_path", "the fitted model")
    data = doc.get("data") or {}
    if not isinstance(data, dict) or not isinstance(data.get("metadata") or {}, dict):
        raise ModelFileError(f"{where}: 'data' must be a JSON object; re-create it with fit")
    if trusted and data.get("env_id") != trusted:
        raise ConfigError(
            f"--env {trusted} is not the system the data of {where} came from "
            f"({data.get('env_id')!r}); name that one, or fit data of {trusted}"
        )
    if data.get("env_id"):
        env_id, env_kwargs = checked_env(data["env_id"], data.get("env_kwargs"), where, trusted)
        if task is not None:
            check_real_env(task, env_id, env_kwargs, where)
        return {"env_id": env_id, "env_kwargs": env_kwargs}
    params = (data.get("metadata") or {}).get("params")
    return {"params": params} if isinstance(params, dict) else None


def checked_env(
    env_id: Any, env_kwargs: Any, where: str = "a file", trusted: str | None = None
) -> tuple[str, dict]:
    """An environment id and its keyword arguments read from a file: the id as
    ``checked_env_id``, the arguments a JSON object of names to finite numbers (what
    ``--env-arg`` can give), so that nothing a file holds reaches ``gymnasium.make`` but
    numbers.

    Raises:
        ConfigError: one line naming the file and the bad value.
    """
    env_id = env_id if trusted and env_id == trusted else checked_env_id(env_id, where)
    env_kwargs = {} if env_kwargs is None else env_kwargs
    if not scalar_arguments(env_kwargs):
        raise ConfigError(
            f"{where} gives the environment arguments {env_kwargs!r}, not names with finite "
            "numbers (or text, true, false); re-create the file, or pass --env and --env-arg"
        )
    if "render_mode" in env_kwargs:  # rendering imports pygame, looked up on sys.path
        raise ConfigError(
            f"{where} asks the environment to render ({env_kwargs['render_mode']!r}); "
            "diffcontrol makes environments named by files without rendering: drop "
            "render_mode from the file"
        )
    return env_id, dict(env_kwargs)


def check_real_env(task: Any, env_id: str, env_kwargs: dict, where: str) -> None:
    """Refuse arguments of an environment that is the task's system with other physics
    (``params_of_env``) whose values the simulator has no meaning for (``check_params``: a
    gravity of 1e308, a negative friction).

    Raises:
        ConfigError: one line naming the file, the environment and the bad parameter.
    """
    params = _gym.params_of_env(task, env_id, env_kwargs)
    if params is None:
        return
    try:
        check_params(task, params)
    except ConfigError as e:
        raise ConfigError(f"{where} names the real system {env_id} {env_kwargs}: {e}") from None


def checked_env_id(env_id: Any, where: str = "a file") -> str:
    """``env_id`` read from a file, if using it imports nothing a file could have chosen.

    The id must be registered with Gymnasium (the built-in ones, diffcontrol's own, and those
    of packages this process has imported), or be ``module:Env-v0`` with ``module`` already
    imported (e.g. by this process's own recording). An id whose environment lives in a
    module not imported yet (Gymnasium's Box2D or MuJoCo environments) has that module
    imported here, from the installed packages alone: the current directory is taken off
    ``sys.path`` meanwhile, so that a ``./Box2D.py`` is never what runs.

    Raises:
        ConfigError: the id is not a string, names a module that is not imported, is not
            registered, or its environment's module does not import: one line saying to pass
            ``--env`` explicitly or what to install.
    """
    import gymnasium

    if not isinstance(env_id, str) or not env_id or env_id.count(":") > 1:
        raise ConfigError(f"{where} names the environment {env_id!r}, not an id; pass --env")
    module, sep, name = env_id.partition(":")
    if sep and module not in sys.modules:
        raise ConfigError(
            f"{where} names the environment {env_id!r}, whose module {module!r} would have to "
            f"be imported; diffcontrol does not import modules named by files: pass "
            f"--env {env_id} explicitly if you trust it"
        )
    spec = gymnasium.registry.get(name if sep else env_id)
    if spec is None:
        raise ConfigError(
            f"{where} names the environment {env_id!r}, which Gymnasium does not know here; "
            "import or install the package that registers it, or re-create the file from a "
            'registered environment (`python -c "import gymnasium; gymnasium.pprint_registry()"` '
            "lists them)"
        )
    entry = spec.entry_point
    if isinstance(entry, str) and entry.partition(":")[0] not in sys.modules:
        _import_installed(entry.partition(":")[0], env_id, where)
    return env_id


def _import_installed(module: str, env_id: str, where: str) -> None:
    """Import ``module`` (an environment's, from Gymnasium's registry) with the current
    directory off ``sys.path``, so that only installed packages are found."""
    import importlib

    here = {"", ".", os.getcwd()}
    saved = list(sys.path)
    sys.path[:] = [p for p in sys.path if p not in here]
    try:
        importlib.import_module(module)
    except Exception as e:  # noqa: BLE001 - a missing optional dependency, said in one line
        raise ConfigError(
            f"{where} names the environment {env_id!r}, which cannot be made here "
            f"({type(e).__name__}: {' '.join(str(e).split())[:160]}); install what it needs"
        ) from None
    finally:
        sys.path[:] = saved


def as_env(real: dict | None) -> tuple[str, dict] | None:
    """``(env_id, env_kwargs)`` of a real system that is a Gymnasium environment, else None."""
    return (real["env_id"], real["env_kwargs"]) if real and "env_id" in real else None


def real_params(task: Any, real: dict | None) -> Any:
    """The task's parameters of a real system given by its parameters (data recorded from the
    task's own simulator with other parameters), else None."""
    if not real or "params" not in real:
        return None
    values = real["params"]
    if not isinstance(values, dict) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in values.values()
    ):
        raise ModelFileError(f"the real system's parameters {values!r} are not finite numbers")
    params = fitted_physics(task, {"task": task.name, "all_parameters": values})
    check_params(task, params)  # the ranges, as for --param
    return params


@task_hook
def fitted_task(task: Any, doc: dict) -> Any:
    """``task`` with its simulator replaced by the hybrid or neural model of a ``fitted.json``
    document (``diffcontrol train --model``); a task with a model of its own overrides it
    (the swing-ups) as ``tasks._hooks`` says.

    Raises:
        ConfigError: a continuous-time task that defines no fitted task of its own.
    """
    if not isinstance(task, Task):
        raise ConfigError(
            f"task {task.name!r} cannot be trained through a fitted model (it defines no "
            "fitted_task)"
        )
    return model_task(task, fitted_model(task, doc))
