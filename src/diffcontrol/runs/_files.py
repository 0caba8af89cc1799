"""Run directories written and read back: ``save_run``, ``open_run`` and ``run.json``."""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .. import _timing, io, policies
from ..errors import ModelFileError
from ..evaluation import evaluate_run
from ..tasks import AnyTask, resolve

MODEL_FILE = "model.json"
METRICS_FILE = "metrics.json"


@dataclasses.dataclass
class Run:
    """A trained controller with what it needs to be judged and drawn.

    Attributes:
        task: the task whose hooks judge and draw it (for a run trained through a fitted
            model: the modelled system's task, when the real system is given by parameters).
        controller: the JAX ``MLPController`` (``None`` for a planner read back: see ``policy``).
        config: the training configuration (from ``run.json``, else the task's default).
        params: the physical parameters to simulate with (the real system's where known).
        model: the ``model.json`` document.
        metrics: ``metrics.json`` (empty before it is written).
        real: the system it is judged on instead of the task's own: ``{"env_id",
            "env_kwargs"}`` (a Gymnasium environment) or ``{"params"}``; ``None``: the task's.
    """

    task: AnyTask
    controller: Any
    config: Any
    params: Any
    model: dict
    metrics: dict = dataclasses.field(default_factory=dict)
    real: dict | None = None
    memo: dict = dataclasses.field(default_factory=dict, repr=False)
    """Results the task's hooks share (e.g. one reference solve for evaluation and plots)."""

    @functools.cached_property
    def policy(self) -> Any:
        """The policy of ``model`` (``load_policy``)."""
        return load_policy(self.task, self.model)

    @property
    def feedback(self) -> Any:
        """What closes a continuous-time task's loop: ``controller`` (inside the ODE), or for
        a planner, which has none, ``policy`` (an ``mpc.SampledPlannerPolicy``, each action
        held for its ``dt``: ``evaluation.simulate_continuous`` takes either)."""
        return self.policy if self.controller is None else self.controller

    @property
    def real_env(self) -> tuple[str, dict] | None:
        """``(env_id, env_kwargs)`` where the run is judged in another Gymnasium environment."""
        if self.real and "env_id" in self.real:
            return self.real["env_id"], dict(self.real.get("env_kwargs") or {})
        return None


def load_policy(task: AnyTask, doc: dict) -> Any:
    """The policy of a ``model.json`` document: the task's ``load_policy`` (a NumPy policy),
    or for a planner its ``mpc.PlannerPolicy`` (which imports JAX)."""
    if policies.is_planner(doc):
        from ._plan import planner_policy

        return planner_policy(task, doc)
    return task.load_policy(doc)


def load(run_dir: str | os.PathLike, task: AnyTask | str | None = None) -> Any:
    """Load the controller saved in ``run_dir`` (a run directory or its ``model.json``) as a
    NumPy policy, for any task.

    The policy is the task's (its ``load_policy`` hook): by default a ``NumpyPolicy``,
    ``policy(obs)`` -> a valid Gymnasium action, which drops into a plain
    ``gymnasium.make(...)`` loop; an ``AimingPolicy`` for the trebuchet
    (``policy(target_m, wind_mps) -> (angle_deg, weight_lb)``); a ``StatePolicy`` for a
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
        ModelFileError: the file is missing, corrupt, or of an unsupported version.
    """
    from .. import tasks
    from ..policies import NumpyPolicy, StatePolicy, read_model

    doc = read_model(Path(run_dir))
    if isinstance(task, str):
        task = tasks.resolve(task)
    if task is None and doc["task"] in tasks.names():
        task = tasks.make(doc["task"])
    if task is not None:
        return load_policy(task, doc)  # the task's, or a planner's
    if policies.is_planner(doc):
        raise ModelFileError(f"the planner's task {doc['task']!r} is not registered; pass task=")
    return StatePolicy(doc) if "features" in doc["observation"] else NumpyPolicy(doc)


def _judged(task: AnyTask, params: Any, real: dict | None) -> tuple[AnyTask, Any]:
    """The task and parameters a run is judged with: a run trained through a fitted model is
    judged on the system the model stands for (``task.base``) with the real parameters where
    its data gives them, else on what it was trained on."""
    if real and "params" in real:
        from ..identify.fitted import real_params

        base = getattr(task, "base", task)
        return base, real_params(base, real)
    return task, params


def save_run(
    result: Any,
    out_dir: str | Path,
    *,
    final_eval: int | None = None,
    animation: bool = True,
    real: dict | None = None,
    progress: Callable[[str], None] | None = None,
    process_total: bool = False,
) -> tuple[Run, list[str]]:
    """Write a trained controller's run files into ``out_dir``: ``model.json``, the final
    evaluation in ``metrics.json`` and the task's pictures.

    Args:
        result: a ``TrainResult``.
        final_eval: episodes (or situations) of the final evaluation; ``None``: the task's
            ``default_eval_episodes``; ``0`` skips it.
        animation: write the task's animation (``rollout.gif``) where it has one.
        real: the system to judge it on instead of the task's own (see ``Run.real``).
        progress: called with a line when the evaluation is done.
        process_total: record the process's age in ``metrics["timings"]["total"]`` (the
            command line, whose process is the run).

    Returns:
        The ``Run`` and the names of the files written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda line: None)
    metrics = dict(result.metrics)
    metrics.setdefault("created", io.now_iso())
    timings = metrics["timings"] = dict(metrics.get("timings") or {})
    own = getattr(result, "model_document", None)  # a planner's (runs.plan_run)
    doc = (
        own(metrics)
        if own
        else policies.model_document(result.task, result.controller, result.config, metrics)
    )
    io.write_json(out / MODEL_FILE, doc)
    task, params = _judged(result.task, result.params, real)
    run = Run(task, result.controller, result.config, params, doc, metrics, real)
    if getattr(result, "policy", None) is not None:  # built already: not built again
        run.__dict__["policy"] = result.policy
    if final_eval != 0 or not task.final_eval_skippable:
        t0 = time.perf_counter()
        with _timing.phase(timings, "evaluate"):
            ev = evaluate_run(task, run, episodes=final_eval, seed=0)
        if ev is not None:
            metrics[ev.key] = {**ev.to_json(), "seconds": time.perf_counter() - t0}
            metrics["final_evaluation"] = ev.key
            where = " on the real system" if real else ""
            say(f"final evaluation{where}: {ev.summary()}")
            run.metrics["headline"] = ev.headline()
    with _timing.phase(timings, "write"):
        from .. import plots

        files = [MODEL_FILE, METRICS_FILE]
        if "curve" in metrics:  # a planner has none
            plots.learning_curve(
                metrics, out / "learning_curve.png", getattr(task, "reward_threshold", None)
            )
            files.append("learning_curve.png")
        from ._figures import write_figures  # matplotlib, when pictures are drawn

        files += write_figures(task, run, out, animation=animation)
    if process_total:
        timings["total"] = _timing.process_seconds()
    # metrics.json last: its timings include the pictures
    io.write_json(out / METRICS_FILE, {k: v for k, v in metrics.items() if k != "headline"})
    return run, files


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
    for what, key in (("observation", "observation_size"), ("action", "action_size")):
        size, own = doc[what]["size"], getattr(task, key, None)
        if isinstance(own, int) and size != own:  # a model of another system: refused here
            raise ModelFileError(
                f"{path} holds a controller of {what} size {size}, but task {task.name!r} has "
                f"{what}s of size {own}; open it with its own task (--task)"
            )
    config = task.default_config()
    planner = policies.is_planner(doc)  # its run.json holds the planner's settings, not training's
    if (directory / io.RUN_FILE).exists() and not planner:
        stored = io.read_json(directory / io.RUN_FILE, "run file").get("config")
        try:
            config = type(config).from_json(stored)
        except (TypeError, ValueError, KeyError, AttributeError) as e:
            raise ModelFileError(
                f"{directory / io.RUN_FILE} holds settings this task cannot read ({e}); "
                "re-create the run with `diffcontrol train`"
            ) from None
    metrics = {}
    if (directory / METRICS_FILE).exists():
        metrics = io.read_json(directory / METRICS_FILE, "metrics")
        if not isinstance(metrics, dict):
            raise ModelFileError(f"{directory / METRICS_FILE} is not a JSON object")
    if real is True:
        model = metrics.get("model")
        real = model.get("real_system") if isinstance(model, dict) else None
        if real is not None and not isinstance(real, dict):
            raise ModelFileError(f"{directory / METRICS_FILE}: 'real_system' is not an object")
        if real and "env_id" in real:  # read from a file: used only if it imports nothing
            from ..identify.fitted import checked_env

            env = checked_env(real["env_id"], real.get("env_kwargs"), str(directory / METRICS_FILE))
            real = {"env_id": env[0], "env_kwargs": env[1]}
    from ..training import task_params

    task, params = _judged(task, task_params(task, config.params), real or None)
    controller = None if planner else policies.controller_from_dict(doc)  # a planner: run.policy
    return Run(task, controller, config, params, doc, metrics, real or None)


def _task_of(doc: dict) -> AnyTask:
    """The registered task a ``model.json`` names (never imported because a file says so)."""
    from .. import tasks

    source = (doc.get("metadata") or {}).get("task_source")
    hint = f" (it was trained from {source!r})" if isinstance(source, str) else ""
    fix = f"--task module:Class{hint} (in Python: open_run(dir, task=...))"
    return tasks.named_by_file(doc["task"], "the controller", fix)


def read_run_file(run_dir: str | Path) -> dict | None:
    """``run.json`` of ``run_dir`` (what the run is and how it was started), or ``None``."""
    path = Path(run_dir) / io.RUN_FILE
    if not path.is_file():
        return None
    doc = io.read_json(path, "run file")
    if not isinstance(doc, dict) or not isinstance(doc.get("config"), dict):
        raise ModelFileError(f"{path} is not a diffcontrol run file; choose another --out")
    return doc


def mark_complete(run_dir: str | Path) -> None:
    """Record in ``run.json`` that the run and its files are finished (a resume then has
    nothing to do and changes nothing)."""
    doc = read_run_file(run_dir) or {}
    io.write_json(Path(run_dir) / io.RUN_FILE, {**doc, "complete": True})


def release_claim(run_dir: str | Path) -> bool:
    """After a run failed before its first checkpoint, give its directory back: remove the
    ``run.json`` it claimed the directory with (and the directory, if that leaves it empty),
    so that the corrected command can use it. Returns whether it did."""
    out = Path(run_dir)
    doc = read_run_file(out)
    if doc is None or doc.get("complete") or (out / "checkpoint.npz").exists():
        return False
    (out / io.RUN_FILE).unlink()
    if not any(out.iterdir()):
        out.rmdir()
    return True
