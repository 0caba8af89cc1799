"""Training into a run directory: what ``diffcontrol train`` does, as one library call.

``train_run`` resolves the task and the settings (from the arguments, or from the run's own
``run.json`` when resuming), trains (``diffcontrol.train``), writes the run's files
(``save_run``) and marks the run complete. Interrupted, it raises ``RunInterrupted`` with the
command that continues it.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import _jax_setup, _run_dir, _timing, io, tasks
from .._run_files import Run, mark_complete, read_run_file, release_claim, save_run
from .._shell import command as shell_command
from ..envs import make_env
from ..errors import (
    ConfigError,
    Interrupted,
    ModelFileError,
    RunDirectoryError,
    TrainingDiverged,
)
from ..identify.fitted import checked_env_id, fitted_physics, fitted_task, read_fitted, real_system
from ..identify.kinds import kind
from ..mpc._config import default_plan_config, loop_planner, plans_best
from ..tasks import AnyTask, named_by_file, resolve
from ..training import resolve_config, train
from ..training._devices import is_writer, join_hosts
from ..training._driver import CHECKPOINT_FILE
from ..training._ode import windows_of
from ._open import open_run


class RunInterrupted(Interrupted):
    """Training or writing was interrupted (Ctrl-C); the message says what was kept and the
    command that continues the run, if anything can be continued."""


@dataclasses.dataclass
class RunOutcome:
    """What ``train_run`` did: the run (``None`` if it was finished before), the files it
    wrote, the one-line summary of ``diffcontrol train`` and its last line, where the time
    went (``metrics["timings"]``); ``advice``: the command of a better controller, where the
    task's planner does better than its trained MLP (``mpc._config.plans_best``)."""

    run: Run | None
    files: list[str]
    summary: str
    timings: str = ""
    advice: str = ""


def train_run(
    out_dir: str | Path,
    task: str | None = None,
    *,
    recipe: str | None = None,
    settings: dict[str, Any] | None = None,
    params: tuple[tuple[str, float], ...] = (),
    model: str | Path | None = None,
    env_id: str | None = None,
    resume: bool = False,
    final_eval: int | None = None,
    animation: bool = True,
    devices: int | None = None,
    hosts: tuple[str, int, int, float] | None = None,
    compile_cache: bool = True,
    progress: Callable[[str], None] | None = None,
    note: Callable[[str], None] | None = None,
    inform: Callable[[str], None] | None = None,
    command: str | None = None,
    log_dir: str | Path | None = None,
    init: str | Path | None = None,
) -> RunOutcome:
    """Train a controller into ``out_dir`` and write its files, as ``diffcontrol train``.

    Args:
        out_dir: the run directory (new or empty; with ``resume``, the run to continue).
        task: a task name or import path (``module:Class``); with ``resume`` it may be left
            out, and the run's own is taken (if it is registered: nothing is imported because
            a file names it).
        recipe: a named set of settings of the task (``--recipe``).
        settings: config field overrides (``None`` values skipped).
        params: physical parameter overrides ``(name, value)`` (they win over a grey box's).
        model: a directory written by ``diffcontrol fit``: train through that model, judge on
            the system its data came from.
        env_id: with ``model``, the Gymnasium id of the real system when the fitted model's
            data names one in a module that is not imported (``module:Env-v0``): named here,
            by the user, it may be imported; a file's id never is.
        resume: continue the run in ``out_dir``; everything not given comes from its
            ``run.json``; a finished run is left untouched.
        final_eval: the final evaluation's size (``None``: the task's default; 0 skips).
        animation: whether to write the animation.
        devices: split the batch over this many devices (``train``'s ``devices``; default
            one, or all devices of all hosts in a multi-host run).
        hosts: ``(coordinator "HOST:PORT", processes, process_id, timeout_s)``: join a multi-host run
            first (``jax.distributed.initialize``). Every process runs the same call; process
            0 writes the run directory (resuming needs it on a file system all hosts see).
        compile_cache: use JAX's persistent compilation cache.
        progress: called with each progress line.
        note: called with warnings meant for stderr.
        inform: called with what is trained through (even when ``progress`` is silent).
        command: the command line to record in ``metrics.json``.
        log_dir: write the training curves there as TensorBoard event files (``train``'s).
        init: a trained run's directory whose controller the training starts from
            (``train``'s ``init``; a resume reads it from ``run.json`` where it has no
            checkpoint yet).

    Raises:
        ConfigError, RunDirectoryError, ModelFileError, TrainingDiverged, SolverFailed: bad
            settings or files, or a failed run (its directory is given back if nothing could
            be kept).
        RunInterrupted: Ctrl-C; the message says how to continue.
    """
    started = _timing.process_seconds()  # the interpreter, the imports, the command line

    if hosts is not None:
        join_hosts(*hosts)
    say = progress or (lambda line: None)
    note = note or (lambda line: print(line, file=sys.stderr))
    out = Path(out_dir)
    stored = read_run_file(out) if resume else None
    if stored and stored.get("planner"):
        raise RunDirectoryError(f"{out} holds a planner (diffcontrol plan); nothing to resume")
    invocation = (stored or {}).get("invocation") or {}
    if task is None:
        task = invocation.get("task") or (stored or {}).get("task")
        if stored is None:
            raise ConfigError("name the TASK to train (or --resume the run in --out)")
        fix = shell_command("train", str(task), "--out", out, "--resume")
        task = named_by_file(task, str(out / _run_dir.RUN_FILE), fix).name
    model = model or invocation.get("model")
    if env_id and not model:
        raise ConfigError("--env names the real system of a fitted model: give --model too")
    if env_id is None and invocation.get("env"):  # run.json's: used if it imports nothing
        env_id = checked_env_id(invocation["env"], str(out / _run_dir.RUN_FILE))
    final_eval = invocation.get("final_eval") if final_eval is None else final_eval
    animation = animation and invocation.get("animation") is not False
    devices = devices or invocation.get("devices")
    init = init or invocation.get("init")
    spec, the_task = task, resolve(task)

    config_cls = type(the_task.default_config())
    fields = {f.name for f in dataclasses.fields(config_cls)}
    overrides = {n: v for n, v in (settings or {}).items() if v is not None}
    foreign = sorted(n for n in overrides if n not in fields)
    if foreign:
        flags = ", ".join("--" + n.replace("_", "-") for n in foreign)
        raise ConfigError(
            f"{flags} do{'es' if len(foreign) == 1 else ''} not apply to {the_task.name!r} "
            f"(trained with a {config_cls.__name__}); see `diffcontrol train --help` for the "
            "settings of each kind of task"
        )
    fitted_params, real, model_info = (), None, None
    if model:
        the_task, fitted_params, real, model_info = fitted_training(the_task, model, params, env_id)
        (inform or print)(model_info.pop("note"))
    if fitted_params or params:
        overrides["params"] = (*fitted_params, *params)  # params win
    if stored is not None and recipe is None:  # run.json's settings, then what was given
        config = config_cls.from_json(stored["config"])  # (a fitted model's params included)
        config = config.replace(**overrides) if overrides else config
    else:
        config = resolve_config(the_task, recipe, **overrides)

    if stored is not None and stored.get("complete"):
        _run_dir.check_same_run(out, stored, {"task": the_task.name, "config": config.to_json()})
        return RunOutcome(None, [], f"{out} holds a finished run; nothing to resume")

    cache_dir = None
    if compile_cache and not os.environ.get("DIFFCONTROL_NO_COMPILE_CACHE"):
        cache_dir = _jax_setup.enable_compile_cache()
    if getattr(config, "gradient", None) == "backsolve":
        note(
            "note: --gradient backsolve is the continuous adjoint: its gradient is "
            "approximate (the backward solve re-creates the state with the solver's error); "
            "checkpoint is exact for the computed solve"
        )
    # a resumed run with a checkpoint starts from that, not from the run it was started from
    checkpointed = resume and (out / CHECKPOINT_FILE).is_file()
    start = _controller_of(init, the_task) if init and not checkpointed else None
    invocation = {"task": spec, "model": model, "final_eval": final_eval, "animation": animation}
    if devices:
        invocation["devices"] = devices
    if init:  # absolute: a resume may run from another directory
        invocation["init"] = os.path.abspath(init)
    if env_id:
        invocation["env"] = env_id
    named = [] if spec in _builtin_names() else [spec]
    # the command that continues this run: run.json gives all but a module to import
    resume_command = shell_command(
        "train",
        *named,
        "--out",
        out,
        "--resume",
        *(["--env", env_id] if env_id and ":" in env_id else []),
    )
    say(describe(the_task, config, out))  # the first line; an interrupt after it is caught
    try:
        result = train(
            the_task,
            config,
            out_dir=out,
            resume=resume,
            progress=say,
            invocation=invocation,
            devices=devices,
            log_dir=log_dir,
            init=start,
        )
    except BaseException as e:
        # nothing to resume (no run.json yet, or one without a checkpoint): say so
        kept = (
            resume
            or not is_writer()
            or (not release_claim(out) and (out / _run_dir.RUN_FILE).is_file())
        )
        if isinstance(e, TrainingDiverged) and kept and not resume:  # other settings: new dir
            raise type(e)(
                f"{e}; train with the changed settings into a new --out ({out} keeps this run)"
            ) from None
        if not isinstance(e, KeyboardInterrupt):
            raise
        if not kept:
            raise RunInterrupted(
                "interrupted before the first checkpoint; nothing was kept"
            ) from None
        raise RunInterrupted(
            f"interrupted; the last checkpoint is in {out}. Continue with: {resume_command}"
        ) from None
    metrics = result.metrics
    metrics["compile_cache"] = {
        "dir": str(cache_dir) if cache_dir else None,
        **_jax_setup.cache_events(),
    }
    metrics["command"] = command
    if started is not None:
        metrics["timings"] = {"import": started, **metrics["timings"]}
    metrics["created"] = io.now_iso()
    if model_info:
        metrics["model"] = model_info
    if not is_writer():  # process 0 of the hosts writes the files
        return RunOutcome(None, [], f"process {hosts[2]} of {hosts[1]}: done")
    try:
        run, files = save_run(
            result,
            out,
            final_eval=final_eval,
            animation=animation,
            real=real,
            progress=say,
            process_total=True,
            overwrite=True,  # the directory train_run claimed
        )
    except KeyboardInterrupt:
        raise RunInterrupted(
            f"interrupted while writing the run's files; finish them with: {resume_command}"
        ) from None
    mark_complete(out)
    headline = run.metrics.get("headline")
    summary = (
        f"done in {metrics['train_seconds']:.1f} s (compile {metrics['compile_seconds']:.1f} s): "
        f"{metrics['simulated_episodes']:.4g} simulated episodes ({metrics['simulated_steps']} "
        f"steps)" + (f"; {headline}" if headline else "") + (" on the real system" if real else "")
    )
    timings = _timing.describe(run.metrics["timings"])
    return RunOutcome(run, files, summary, timings, _advice(the_task, out, model or params))


def _controller_of(run_dir: str | Path, task: AnyTask) -> Any:
    """The trained controller in ``run_dir`` (``--init``), read for ``task``.

    Raises:
        ModelFileError: no run there, a damaged one, or one of another system (its
            observation or action size), named as ``--init``'s.
        ConfigError: a planner's run (it has no network to start from).
    """
    try:
        controller = open_run(run_dir, task=task).controller
    except ModelFileError as e:  # named as --init's, without open_run's advice to name --task
        raise ModelFileError(f"--init {run_dir}: {str(e).split('; open it with')[0]}") from None
    if controller is None:
        raise ConfigError(
            f"--init {run_dir}: a planner has no network to start from; give a trained run"
        )
    return controller


def _advice(task: AnyTask, out: Path, changed: Any) -> str:
    """Where the task's planner does better than the MLP on its own physics (``plans_best``:
    the Pendulum, docs/planning.md), the command that plans."""
    if changed or not isinstance(task, tasks.Task) or not plans_best(task):
        return ""
    p, own = loop_planner(task), default_plan_config(task)
    plan = ["plan", task.name]  # the flags of the loop's planner that plan's defaults lack
    for name in ("horizon", "value_grid"):
        if getattr(p, name) != getattr(own, name):
            plan += ["--" + name.replace("_", "-"), str(getattr(p, name))]
    return (
        f"a planner does better on {task.name} than this MLP (docs/planning.md); it needs JAX "
        f"to act: {shell_command(*plan, '--out', f'{out}-plan')}"
    )


def _builtin_names() -> set[str]:
    return {n for n in tasks.names() if not getattr(tasks.make(n), "source", None)}


def describe(task: AnyTask, config: Any, out: Path | str) -> str:
    """The line ``diffcontrol train`` starts with: what will be trained, how, and where."""
    if hasattr(config, "horizon_s"):  # an ODETrainConfig
        k = windows_of(config)
        windows = f" in {k} windows of {config.horizon_s / k:g} s" if k > 1 else ""
        return (
            f"training {task.name}: {config.updates} updates of {config.population} closed-loop "
            f"solve(s) over {config.horizon_s:g} s{windows} ({config.solver}, rtol "
            f"{config.rtol:g}, atol {config.atol:g}, gradient {config.gradient}; seed "
            f"{config.seed}) -> {out}"
        )
    window = f"window {config.window}"
    if config.final_window_start < config.updates:  # the window curriculum's last stage
        window += f" (from update {config.final_window_start}: {config.final_window})"
    return (
        f"training {task.name}: {config.updates} updates x {window} x batch "
        f"{config.batch} (seed {config.seed}) -> {out}"
    )


def fitted_training(
    task: AnyTask, fit_dir: str | Path, params: Any = None, env_id: str | None = None
) -> tuple[AnyTask, tuple, dict | None, dict]:
    """What training through the model that ``diffcontrol fit`` wrote in ``fit_dir`` needs.

    Returns:
        The task to train (a hybrid or neural model's own; ``task`` for a grey box), the
        fitted physical parameters as ``(name, value)`` overrides (grey box), the real system
        the data came from (``identify.real_system``; ``None`` where the data does not say) and
        ``metrics["model"]`` with a printable ``"note"``.

    Raises:
        ConfigError: ``params`` would change the physics of a hybrid or neural model.
        ModelFileError: the fitted file is missing, corrupt or of another task.
    """
    import numpy as np

    doc = read_fitted(fit_dir)
    fitted_physics(task, doc)  # refuses a model of another task
    real = real_system(doc, trusted=env_id, task=task)
    if real and "env_id" in real:  # the final evaluation's environment, made before training
        make_env(real["env_id"], real["env_kwargs"]).close()
    info = {"dir": str(fit_dir), "kind": doc["model"], "real_system": real}
    if not kind(doc["model"]).network:
        info["note"] = f"training through the fitted parameters in {fit_dir}"
        return task, tuple(sorted(doc["all_parameters"].items())), real, info
    if params:
        raise ConfigError(
            f"--param cannot change the physics of the {doc['model']} model in {fit_dir}; "
            "refit it, or train with a grey-box (--model params) fit"
        )
    fitted = fitted_task(task, doc)
    nets = doc["network"].get("members") or [doc["network"]]  # an ensemble's, or the one
    weights = sum(
        np.asarray(l["weight"]).size + len(l["bias"]) for n in nets for l in n.get("layers", [])
    )
    of = f"{len(nets)} networks, " if len(nets) > 1 else ""
    info["note"] = (
        f"training through the {doc['model']} model in {fit_dir} ({of}{weights} network weights)"
    )
    if len(nets) > 1:
        info["note"] += (
            f": their mean, plus {fitted.default_params().correction.penalty:g} x their spread "
            "in every step's loss"
        )
    return fitted, (), real, info
