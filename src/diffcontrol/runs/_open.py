"""Run directories read back: ``load`` (``diffcontrol.load``: the policy alone, NumPy where it
can be) and ``open_run`` (the controller with its task, settings, parameters and metrics)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from .. import _run_dir, io, policies, tasks
from .._run_files import METRICS_FILE, Run, judged, task_policy
from ..errors import ModelFileError
from ..identify.fitted import checked_env
from ..mpc import planner_policy
from ..policies import NumpyPolicy, StatePolicy, read_model
from ..tasks import AnyTask, resolve, task_params


def load_policy(task: AnyTask, doc: dict) -> Any:
    """The policy of a ``model.json`` document: the task's ``load_policy`` (a NumPy policy),
    or for a planner its ``mpc.PlannerPolicy`` (which imports JAX)."""
    if policies.is_planner(doc):
        return planner_policy(task, doc)
    return task_policy(task, doc)


def load(run_dir: str | os.PathLike, task: AnyTask | str | None = None) -> Any:
    """Load the controller saved in ``run_dir`` (a run directory or its ``model.json``) as a
    NumPy policy, for any task.

    The policy is the task's (its ``load_policy`` hook): by default a ``NumpyPolicy``,
    ``policy(obs)`` -> a valid Gymnasium action, which drops into a plain
    ``gymnasium.make(...)`` loop; an ``AimingPolicy`` for the trebuchet
    (``policy(target_m, wind_mps) -> (angle_deg, weight_lb)``; a run trained since the aim is
    refined at act time loads as a ``RefinedAimingPolicy``, which runs that refinement through
    the simulator with JAX, and whose ``network_action`` is the NumPy-only network); a
    ``StatePolicy`` for a
    continuous-time task (``policy(state) -> action`` on the physical state). A planner
    (written by ``diffcontrol plan``) loads as an ``mpc.PlannerPolicy``, ``policy(obs)`` ->
    Gymnasium action like the others, but it imports JAX and runs one compiled solve per
    call (its terminal value grid, if any, is solved again here from the stored settings);
    a continuous-time task's planner as an ``mpc.SampledPlannerPolicy``, ``policy(state)`` ->
    action like a ``StatePolicy``, but an action to hold for ``policy.dt`` seconds (one
    solve per control period, JAX again).

    Args:
        run_dir: a directory written by ``diffcontrol train`` or ``result.save``.
        task: the task (or its name or import path) when it is not registered; without it a
            task that is not registered loads by the file's format alone (a ``NumpyPolicy``,
            or a ``StatePolicy`` where the file gives the state's features).

    Raises:
        ModelFileError: the file is missing, corrupt, or of an unsupported version, or a
            controller of other sizes than ``task``'s.
    """
    doc = read_model(Path(run_dir))
    if isinstance(task, str):
        task = tasks.resolve(task)
    if task is None and doc["task"] in tasks.names():
        task = tasks.make(doc["task"])
    if task is not None:
        _check_sizes(doc, task, run_dir)
        return load_policy(task, doc)  # the task's, or a planner's
    if policies.is_planner(doc):
        raise ModelFileError(f"the planner's task {doc['task']!r} is not registered; pass task=")
    return StatePolicy(doc) if "features" in doc["observation"] else NumpyPolicy(doc)


def open_run(
    run_dir: str | Path, task: AnyTask | str | None = None, real: dict | None | bool = True
) -> Run:
    """Read a run directory (or a ``model.json``) back into a ``Run``.

    Args:
        run_dir: a directory written by ``diffcontrol train`` (or its ``model.json``).
        task: the task (or a name, or an import path ``module:Class``); default: the
            registered task that ``model.json`` names. A user's task is never imported
            because a file names it: pass it here (``--task`` on the command line).
        real: ``True``: the real system recorded in ``metrics.json`` (a run trained through a
            fitted model); a dict: that system instead; ``None``: the task's own.

    Raises:
        ModelFileError: the files are missing or corrupt.
        UnknownTaskError: the task is not registered and not given.
    """
    path = Path(run_dir)
    directory = path if path.is_dir() else path.parent
    doc = policies.read_model(path)
    if task is None:
        task = _task_of(doc)
    elif isinstance(task, str):
        task = resolve(task)
    _check_sizes(doc, task, path)
    config = task.default_config()
    planner = policies.is_planner(doc)  # its run.json holds the planner's settings, not training's
    fitted_model = None  # the --model a run was trained through, as its run.json says
    if (directory / _run_dir.RUN_FILE).exists() and not planner:
        run_doc = io.read_json(directory / _run_dir.RUN_FILE, "run file")
        stored = run_doc.get("config")
        invocation = run_doc.get("invocation")
        fitted_model = invocation.get("model") if isinstance(invocation, dict) else None
        try:
            config = type(config).from_json(stored)
        except (TypeError, ValueError, KeyError, AttributeError) as e:
            raise ModelFileError(
                f"{directory / _run_dir.RUN_FILE} holds settings this task cannot read ({e}); "
                "re-create the run with `diffcontrol train`"
            ) from None
    metrics = {}
    if (directory / METRICS_FILE).exists():
        metrics = io.read_json(directory / METRICS_FILE, "metrics")
        if not isinstance(metrics, dict):
            raise ModelFileError(f"{directory / METRICS_FILE} is not a JSON object")
    if real is True:
        model = metrics.get("model")
        if fitted_model and not (isinstance(model, dict) and "real_system" in model):
            raise ModelFileError(
                f"{directory} was trained through the fitted model {fitted_model} (run.json), "
                f"but its {METRICS_FILE} does not say which real system to judge it on (missing "
                "or damaged); name the system with --env (Python: open_run(dir, real=...))"
            )
        real = model.get("real_system") if isinstance(model, dict) else None
        if real is not None and not isinstance(real, dict):
            raise ModelFileError(f"{directory / METRICS_FILE}: 'real_system' is not an object")
        if real and "env_id" in real:  # read from a file: used only if it imports nothing
            env = checked_env(real["env_id"], real.get("env_kwargs"), str(directory / METRICS_FILE))
            real = {"env_id": env[0], "env_kwargs": env[1]}
    task, params = judged(task, task_params(task, config.params), real or None)
    controller = None if planner else policies.controller_from_dict(doc)  # a planner: run.policy
    return Run(task, controller, config, params, doc, metrics, real or None, loader=load_policy)


def _task_of(doc: dict) -> AnyTask:
    """The registered task a ``model.json`` names (never imported because a file says so)."""
    source = (doc.get("metadata") or {}).get("task_source")
    hint = f" (it was trained from {source!r})" if isinstance(source, str) else ""
    fix = f"--task module:Class{hint} (in Python: open_run(dir, task=...))"
    return tasks.named_by_file(doc["task"], "the controller", fix)


def _check_sizes(doc: dict, task: AnyTask, path: str | os.PathLike) -> None:
    """Refuse a controller of another system than ``task`` (its observation or action size)."""
    for what, key in (("observation", "observation_size"), ("action", "action_size")):
        size, own = doc[what]["size"], getattr(task, key, None)
        if isinstance(own, int) and size != own:
            raise ModelFileError(
                f"{path} holds a controller of {what} size {size}, but task {task.name!r} has "
                f"{what}s of size {own}; open it with its own task (--task)"
            )
