"""A run directory's files: ``save_run`` writes a trained controller's (``TrainResult.save``),
``run.json`` records what the run is; ``runs.open_run`` reads them back."""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from . import _run_dir, _timing, io, policies
from .errors import ModelFileError, RunDirectoryError
from .evaluation import evaluate_run
from .identify.fitted import real_params
from .tasks import AnyTask, ContinuousTask
from .tasks._hooks import task_hook

MODEL_FILE = "model.json"
METRICS_FILE = "metrics.json"


@task_hook(method="load_policy")
def task_policy(task: AnyTask, doc: dict) -> Any:
    """The NumPy policy of a ``model.json`` document (what ``diffcontrol.load`` returns); a
    task changes it with a method ``load_policy(doc)``. Default: a ``NumpyPolicy``,
    ``policy(obs) -> Gymnasium action``; for a continuous-time task a ``StatePolicy``,
    ``policy(state) -> action`` on the physical state."""
    return policies.NumpyPolicy(doc)


@task_policy.register(ContinuousTask)
def _state_policy(task: ContinuousTask, doc: dict) -> Any:
    return policies.StatePolicy(doc)


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
    loader: Callable[[AnyTask, dict], Any] | None = dataclasses.field(default=None, repr=False)
    """Builds ``policy`` from ``(task, model)``: ``runs.load_policy`` for a run read back (a
    planner's too); ``None``: the task's (``task_policy``)."""

    @functools.cached_property
    def policy(self) -> Any:
        """The policy of ``model``, built when first used."""
        if self.loader is not None:
            return self.loader(self.task, self.model)
        return task_policy(self.task, self.model)

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


def judged(task: AnyTask, params: Any, real: dict | None) -> tuple[AnyTask, Any]:
    """The task and parameters a run is judged with: a run trained through a fitted model is
    judged on the system the model stands for (``task.base``) with the real parameters where
    its data gives them, else on what it was trained on."""
    if real and "params" in real:
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
    overwrite: bool = False,
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
        overwrite: write over the files of another run in ``out_dir`` (the commands that
            own their directories pass it).

    Returns:
        The ``Run`` and the names of the files written.

    Raises:
        RunDirectoryError: ``out_dir`` holds another run's ``model.json`` or ``run.json``
            (not the directory ``result`` was trained into), and not ``overwrite``.
    """
    out = Path(out_dir)
    own = getattr(result, "out_dir", None)
    held = [n for n in (MODEL_FILE, _run_dir.RUN_FILE) if (out / n).exists()]
    if held and not overwrite and not (own is not None and _same_dir(own, out)):
        raise RunDirectoryError(
            f"{out} holds another run ({', '.join(held)}); save into a new or empty directory, "
            "or pass overwrite=True to replace it"
        )
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
    task, params = judged(result.task, result.params, real)
    run = Run(task, result.controller, result.config, params, doc, metrics, real)
    if getattr(result, "policy", None) is not None:  # built already: not built again
        run.__dict__["policy"] = result.policy
    # A task whose final evaluation is part of what a run reports, its pictures drawn from it
    # anyway (a reference solve), declares ``final_eval_skippable = False``.
    if final_eval != 0 or not getattr(task, "final_eval_skippable", True):
        t0 = time.perf_counter()
        with _timing.phase(timings, "evaluate"):
            ev = evaluate_run(task, run, episodes=final_eval, seed=0)
        if ev is not None:
            metrics[ev.key] = {**ev.to_json(), "seconds": time.perf_counter() - t0}
            metrics["final_evaluation"] = ev.key
            where = " on the real system" if real else ""
            say(f"final evaluation{where}: {ev.summary()}")
            run.metrics["headline"] = ev.headline()
            if getattr(ev, "warnings", None):  # what the evaluation says went wrong
                metrics["warnings"] = [*metrics.get("warnings", []), *ev.warnings]
    with _timing.phase(timings, "write"):
        from . import plots  # matplotlib, when pictures are drawn

        files = [MODEL_FILE, METRICS_FILE]
        if "curve" in metrics:  # a planner has none
            plots.learning_curve(
                metrics, out / "learning_curve.png", getattr(task, "reward_threshold", None)
            )
            files.append("learning_curve.png")

        files += plots.write_figures(task, run, out, animation=animation)
    if process_total:
        timings["total"] = _timing.process_seconds()
    # metrics.json last: its timings include the pictures
    io.write_json(out / METRICS_FILE, {k: v for k, v in metrics.items() if k != "headline"})
    return run, files


def read_run_file(run_dir: str | Path) -> dict | None:
    """``run.json`` of ``run_dir`` (what the run is and how it was started), or ``None``."""
    path = Path(run_dir) / _run_dir.RUN_FILE
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
    io.write_json(Path(run_dir) / _run_dir.RUN_FILE, {**doc, "complete": True})


def release_claim(run_dir: str | Path) -> bool:
    """After a run failed before its first checkpoint, give its directory back: remove the
    ``run.json`` it claimed the directory with (and the directory, if that leaves it empty),
    so that the corrected command can use it. Returns whether it did."""
    out = Path(run_dir)
    doc = read_run_file(out)
    if doc is None or doc.get("complete") or (out / "checkpoint.npz").exists():
        return False
    (out / _run_dir.RUN_FILE).unlink()
    if not any(out.iterdir()):
        out.rmdir()
    return True


def _same_dir(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name the same directory."""
    try:
        return Path(a).resolve() == Path(b).resolve()
    except OSError:
        return False
