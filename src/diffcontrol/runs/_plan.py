"""Planner run directories: ``plan_run`` (``diffcontrol plan``) writes a planning controller as
a run, and ``mpc.planner_policy`` builds it back from ``model.json`` (``diffcontrol.load``,
``evaluate``, ``animate``).

A planner's ``model.json`` (see ``policies.planner_document``) holds its settings and the model it
plans through: the task's own simulator (``{"kind": "simulator"}``) or the whole
``fitted.json`` of ``diffcontrol fit`` (``{"kind": "fitted", "fitted": {...}}``, networks
included), so the file is self-contained. Unlike an MLP's, it needs JAX at run time: every
action is one compiled solve. A continuous-time task's planner plans through
``mpc.discretise(task, dt)`` and acts as a sampled-data controller (``mpc.SampledPlannerPolicy``:
``policy(state)``, each action held for ``dt``), judged by the task's reference solve with the
planner in the loop (``mpc.ode_closed_loop``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .. import _gym, _run_dir, io, policies
from .._run_files import Run, mark_complete, save_run
from .._version import __version__
from ..errors import ConfigError, ModelFileError
from ..identify.fitted import read_fitted, real_system
from ..mpc import ValueNetwork, make_planner_policy
from ..mpc._config import default_plan_config, for_task
from ..settings import PlanConfig
from ..tasks import AnyTask, Task, resolve, task_params


@dataclasses.dataclass
class PlanResult:
    """A planning controller ready to be saved by ``save_run``, as a ``TrainResult`` is."""

    task: AnyTask
    controller: Any  # None: a planner is its ``policy`` (``Run.feedback``)
    config: Any  # the task's default training config (the run's own settings are ``plan``)
    params: Any
    metrics: dict
    plan: PlanConfig
    model: dict
    policy: Any  # the mpc.PlannerPolicy, built once (its terminal value included)
    value: Any = None  # a learned mpc.ValueNetwork as the terminal cost, stored in model.json

    def model_document(self, metrics: dict) -> dict:
        meta = {"diffcontrol_version": __version__, "created": metrics["created"]}
        value = None if self.value is None else self.value.to_json()
        problem = self.policy.planner.problem  # the planner's own bounds (the task may have none)
        bounds = [np.asarray(b, float).tolist() for b in (problem.low, problem.high)]
        doc = policies.planner_document(self.task, self.plan.to_json(), self.model, meta, value)
        doc["action"].update(low=bounds[0], high=bounds[1])
        return doc


def _give_back(out: Path, keep_dir: bool) -> None:
    """Remove what a failed or interrupted ``plan_run`` wrote into the directory it claimed
    (new or empty then, so every file in it is its own), and the directory if it made it."""
    if not out.is_dir():
        return
    for path in out.iterdir():
        if path.is_file() or path.is_symlink():
            path.unlink()
    if not keep_dir and not any(out.iterdir()):
        out.rmdir()


def read_value(task: AnyTask, value: Any) -> Any:
    """``value`` as an ``mpc.ValueNetwork`` of ``task``: a network as it is, or the JSON file
    ``ValueResult.save`` wrote (``diffcontrol plan --value FILE``; read as JSON, no code).

    Raises:
        ConfigError: a network of another task, or something else; ModelFileError: a file
            that is missing, not JSON, or not a value network of ``task`` of sound shapes.
    """
    if isinstance(value, str | Path):
        doc = io.read_json(value, "value network")
        try:
            return ValueNetwork.from_json(task, doc)
        except ModelFileError as e:
            raise ModelFileError(
                f"value file {value}: {e}; pass one that mpc.learn_value learnt for task "
                f"{task.name!r} (written by ValueResult.save)"
            ) from None
    if not isinstance(value, ValueNetwork) or value.task.name != task.name:
        raise ConfigError(f"value={value!r} is not an mpc.ValueNetwork of task {task.name!r}")
    return value


def plan_run(
    out_dir: str | Path,
    task: AnyTask | str,
    config: PlanConfig | None = None,
    *,
    model: str | Path | None = None,
    env_id: str | None = None,
    final_eval: int | None = None,
    animation: bool = True,
    progress: Callable[[str], None] | None = None,
    value: Any = None,
    settings: dict[str, Any] | None = None,
    invocation: dict[str, Any] | None = None,
) -> tuple[Run, list[str]]:
    """Write a planning controller for ``task`` as a run directory: ``model.json`` (the
    settings and the model), ``metrics.json`` (the final evaluation, per-step solve reports
    counted) and the task's pictures; ``diffcontrol.load``, ``evaluate_dir`` and
    ``animate_dir`` take it like a trained run.

    A continuous-time task's planner plans through ``mpc.discretise(task, dt, substeps)``
    and is judged by the task's own evaluation (the swing-up's reference solve, with the
    planner in the loop and each action held for ``dt``: end state, peak force, swings).

    Args:
        out_dir: a new or empty directory.
        task: a task with action bounds, or a continuous-time one (or its name); a task
            without bounds takes ``config.action_bound``.
        config: the planner's settings (default the task's, ``default_plan_config``);
            what ``dt`` and ``action_bound`` leave open is the task's (``mpc._config.for_task``),
            and ``model.json`` stores them filled in.
        model: a directory (or ``fitted.json``) of ``diffcontrol fit`` to plan through instead
            of the task's simulator; its data's system is then where it is evaluated.
        env_id: with ``model``: the real system's Gymnasium id where the fit names one of yours.
        final_eval: evaluation episodes (``None``: the task's default; 0 skips).
        value: a learned terminal value (``mpc.ValueNetwork``, from ``mpc.learn_value``, or
            the JSON file ``ValueResult.save`` wrote) as the terminal cost, in place of the
            task's default grid value; its weights are stored in ``model.json``.
        settings: fields of ``config`` to change (``None`` values skipped): the command
            line's options, over the task's defaults.
        invocation: how the planner was made, recorded in ``run.json`` (default: its task).

    Returns:
        The ``Run`` and the names of the files written.

    Raises:
        ConfigError: settings the task cannot take.
        RunDirectoryError: ``out_dir`` is in use.
        ModelFileError: a fitted model of another task.

    A failed or interrupted ``plan_run`` leaves nothing in ``out_dir`` (the directory is given
    back), so the same call can run again.
    """
    import time

    task = resolve(task) if isinstance(task, str) else task
    if isinstance(task, Task) and not _gym.knows_state(task):
        raise ConfigError(
            f"task {task.name!r} cannot be planned: a planner acts from the system's state, and "
            "the task does not reconstruct it from an observation (it defines no "
            "state_from_observation)"
        )
    # a value network replaces the task's default grid value, not one the caller asked for
    own_grid = config is None and (settings or {}).get("value_grid") is None
    config = default_plan_config(task) if config is None else config
    unknown = set(settings or {}) - {f.name for f in dataclasses.fields(PlanConfig)}
    if unknown:
        raise ConfigError(f"unknown planner settings {sorted(unknown)}; see PlanConfig's fields")
    config = config.replace(**{k: v for k, v in (settings or {}).items() if v is not None})
    if value is not None and own_grid:
        config = config.replace(value_grid=None)
    config = for_task(config, task)
    say = progress or (lambda line: None)
    if value is not None:
        value = read_value(task, value)
    real, info = None, {"kind": "simulator"}
    if model is not None:
        fitted = read_fitted(model)
        real = real_system(fitted, trusted=env_id, task=task)
        stored = {k: v for k, v in fitted.items() if k != "_path"}  # the file, not where it was
        info = {"kind": "fitted", "fitted": stored}
    run = {"task": task.name, "config": config.to_json(), "planner": True}
    run["invocation"] = invocation or {"task": task.name}
    existed = Path(out_dir).is_dir()  # an empty directory of the user's is left in place
    out = _run_dir.prepare_run_dir(out_dir, run, resume=False)
    try:
        t0 = time.perf_counter()
        policy = make_planner_policy(task, config, info, say, value)
        metrics = {
            "created": io.now_iso(),
            "planner": {"settings": config.to_json(), "build_seconds": time.perf_counter() - t0},
            "model": {"kind": "simulator"},
        }
        if model is not None:  # as train --model records it: evaluate reads the real system
            metrics["model"] = {"dir": str(model), "kind": fitted["model"], "real_system": real}
        planner = policy.planner  # judged with its parameters where it plans through the task
        own = planner.task is task or getattr(planner.task, "continuous", None) is task
        params = planner.problem.params if own else task_params(task)
        config_ = task.default_config()  # the run's training settings: none, the defaults
        result = PlanResult(task, None, config_, params, metrics, config, info, policy, value)
        if final_eval != 0:  # minutes where a step is slow to solve (a MuJoCo model)
            say("final evaluation: one plan solved per step of every episode")
        run_, files = save_run(  # into the directory plan_run claimed
            result,
            out,
            final_eval=final_eval,
            animation=animation,
            real=real,
            progress=say,
            overwrite=True,
        )
    except BaseException:
        _give_back(out, existed)  # nothing half-written: the same command can run again
        raise
    run_.metrics["planner"]["solves"] = policy.summary()
    io.write_json(out / "metrics.json", {k: v for k, v in run_.metrics.items() if k != "headline"})
    mark_complete(out)
    say(f"planner: {policy.summary()}")
    return run_, files
