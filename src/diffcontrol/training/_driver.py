"""The thin Python driver around the jitted chunks: progress, evaluation points, checkpoints."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import signal
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PyTree

from .. import _run_dir, _timing, io, policies
from .._run_files import save_run
from ..checks import validate_task
from ..controllers import MLPController
from ..errors import ConfigError, ModelFileError, TrainingDiverged
from ..tasks import AnyTask, StepLoss, Stroke, Task, TrajectoryLoss, as_task, task_params
from ._checkpoint import load_checkpoint, save_checkpoint
from ._devices import batch_placement, check_devices, divisible, gathered, is_writer, placer
from ._diagnostics import Diagnostics
from ._events import learning_rates, open_log
from ._interface import trainer_kind
from ._loop import Loop
from ._programs import _first_state, _kept_trainer, compile_options, compiled_once
from ._stroke import imitate, stroke

CHECKPOINT_FILE = "checkpoint.npz"

__all__ = ["TrainResult", "TrainingDiverged", "resolve_config", "task_params", "train"]


@dataclasses.dataclass
class TrainResult:
    """What ``train`` returns: the trained controller and everything measured on the way."""

    task: AnyTask
    config: Any  # TrainConfig or ODETrainConfig
    params: PyTree
    controller: MLPController
    metrics: dict[str, Any]
    out_dir: Path | None = dataclasses.field(default=None, repr=False)
    """The run directory ``train`` wrote into (``out_dir``), which ``save`` may write again."""

    @property
    def curve(self) -> list[dict[str, Any]]:
        """The learning curve: one dict per evaluation point."""
        return self.metrics["curve"]

    def save(self, out_dir: str | Path, **options: Any) -> list[str]:
        """Write the run's files into ``out_dir``: ``model.json`` (read back by
        ``diffcontrol.load``), the task's final evaluation in ``metrics.json``, the learning
        curve and the task's pictures; returns the names written. ``options`` are those of
        ``diffcontrol.runs.save_run`` (``final_eval``, ``animation``, ``real``, ``progress``,
        ``overwrite``).

        Raises:
            RunDirectoryError: ``out_dir`` holds another run (not the one ``train`` wrote
                there), unless ``overwrite=True``.
        """
        return save_run(self, out_dir, **options)[1]


def resolve_config(task: AnyTask, recipe: str | None = None, **overrides: Any) -> Any:
    """The task's default config, then a named recipe, then explicit overrides (``None`` skipped)."""
    config = task.default_config()
    if recipe:
        recipes = task.recipes()
        if recipe not in recipes:
            known = ", ".join(recipes) or "none"
            raise ConfigError(f"task {task.name!r} has no recipe {recipe!r}; its recipes: {known}")
        config = config.replace(**recipes[recipe])
    changes = {k: v for k, v in overrides.items() if v is not None}
    return config.replace(**changes) if changes else config


def _progress_line(point: dict[str, Any], total: int) -> str:
    pct = 100.0 * point["update"] / max(total, 1)
    head = f"[{pct:5.1f}%] update {point['update']:>5}/{total}  "
    tail = f"  {point['seconds']:6.1f} s"
    if "eval_loss" in point:  # continuous-time: solves, and the best member's loss
        return head + (
            f"solves {point['simulated_episodes']:6d}  horizon {point['horizon_s']:5.2f} s  "
            f"loss {point['loss']:10.4g}  eval loss {point['eval_loss']:10.4g}" + tail
        )
    return head + (
        f"episodes {point['simulated_episodes']:8.1f}  loss {point['loss']:10.4g}  "
        f"eval return {point['eval_return']:9.2f}" + tail
    )


def train(
    task: AnyTask,
    config: Any | None = None,
    *,
    out_dir: str | Path | None = None,
    resume: bool = False,
    step_loss: StepLoss | None = None,
    trajectory_loss: TrajectoryLoss | None = None,
    progress: Callable[[str], None] | None = None,
    on_point: Callable[[dict[str, Any], MLPController], None] | None = None,
    invocation: dict[str, Any] | None = None,
    devices: int | None = None,
    log_dir: str | Path | None = None,
    init: MLPController | None = None,
) -> TrainResult:
    """Train a controller for ``task`` by differentiating through its simulator.

    A discrete-time task trains by truncated BPTT (``TrainConfig``); a continuous-time one
    (``ContinuousTask``, e.g. ``cartpole-swingup``) by differentiating a loss on its saved
    trajectory through an ODE solve (``ODETrainConfig``). Both run on this driver: progress,
    evaluation points, checkpoints, resume.

    Args:
        task: a task from ``diffcontrol.make`` (or its name).
        config: the settings; ``task.default_config()`` when omitted.
        out_dir: if given, ``run.json`` and a checkpoint after every chunk are written there,
            so an interrupted run can continue with ``resume=True``, and ``model.json`` at the
            end (``result.save(out_dir)`` adds the evaluation and the pictures).
        resume: continue the run in ``out_dir`` from its last checkpoint.
        step_loss: discrete-time tasks: a training loss ``f(params, state, action,
            next_state, reward) -> scalar`` that replaces the task's built-in one.
        trajectory_loss: continuous-time tasks: a loss ``f(trajectory) -> scalar`` of the saved
            trajectory (a ``SwingUpTrajectory`` for the swing-ups) that replaces the task's.
        progress: called with one human-readable line per evaluation point.
        on_point: called with each evaluation point (the dict that joins the curve) and the
            controller at that point (a continuous-time run's best member), e.g. to evaluate it elsewhere. The time spent in it is
            left out of every ``seconds`` and of ``train_seconds`` (and reported as
            ``callback_seconds``); it is not saved in checkpoints, so a resumed run calls it
            only for the points after the resume.
        invocation: what else ``run.json`` records so that a resume needs nothing but the
            directory (the command line's task, fitted model, final evaluation, animation).
        devices: split the batch of simulations over this many local devices (data
            parallelism; discrete-time tasks; the batch must divide evenly). The result is
            one device's up to the order of floating-point sums.
        log_dir: write the training curves there as TensorBoard event files: the loss, the
            gradient norm and the learning rate of every update, the evaluation return of
            every evaluation point (``training._events``; needs tensorboardX).
        init: start from this controller instead of random weights (fine-tuning, e.g. a
            trained run's ``open_run(dir).controller`` at a lower learning rate). It must have
            the network this run would make (the same sizes, activation and head); one
            controller only (``population`` 1). A resumed run starts from its checkpoint.
            Without ``init``, a task that declares a ``stroke`` starts from a network fitted to
            play it (``training._stroke``); others from random weights.

    Returns:
        A ``TrainResult`` whose controller is the one of the best evaluation point when
        ``config.keep_best`` (the default), else the last; ``metrics`` holds
        ``train_seconds`` (wall clock, compilation and evaluation included), ``compile_seconds``
        (every program traced, lowered and compiled or loaded from the persistent cache),
        ``timings`` (this call's ``compile``, ``compile_programs`` and ``train`` without
        compilation: ``diffcontrol._timing``), ``simulated_steps``,
        ``simulated_episodes`` (in the task's standard episode length; closed-loop solves for
        continuous-time tasks, whose ``simulated_steps`` are solver steps), the ``curve``, and
        ``returned_update`` with ``final_eval_return`` (the returned controller's), and
        ``warnings``: what the run's numbers say went wrong (``TrainingWarning``, also warned
        and sent to ``progress``): a loss whose gradient is exactly 0 at the first updates, a
        loss that never moves, ``keep_best`` returning the untrained controller.

    Raises:
        ConfigError, RunDirectoryError, ModelFileError: bad settings or directories, or a
            loss that does not return a scalar.
        TaskCheckError: a method of the task returns the wrong shape or dtype
            (``diffcontrol.checks.validate_task``, before anything is compiled).
        TrainingDiverged: the loss became non-finite (lower the learning rate or clip).
        SolverFailed: every ODE solve of a continuous-time run failed (say why and what to
            change, e.g. raise max_steps).
    """
    _timing.watch_compiles()
    t_start = time.perf_counter()
    compiled_before, programs_before = _timing.compile_seconds(), _timing.compiled_programs()
    task = as_task(task, "train()")
    config = config or task.default_config()
    expected = type(task.default_config())
    if not isinstance(config, expected):
        raise ConfigError(
            f"task {task.name!r} is trained with a {expected.__name__}, got a "
            f"{type(config).__name__}; start from task.default_config()"
        )
    say = progress or (lambda line: None)
    _check_head(task, config)
    log = open_log(log_dir) if is_writer() else None  # a missing tensorboardX: said at once
    params = task_params(task, config.params)
    validate_task(task, params)  # a wrong shape named here, not as a lax.scan type error
    kind = trainer_kind(config)
    losses = {"step_loss": step_loss, "trajectory_loss": trajectory_loss}
    if any(f is not None for name, f in losses.items() if name != kind.loss):
        raise ConfigError(f"task {task.name!r} is {kind.time}: pass {kind.loss}")
    run = {"format": "diffcontrol-run", "task": task.name, "config": config.to_json()}
    if invocation:
        run["invocation"] = invocation
    if out_dir is not None and is_writer():  # before a terminal value's grid is solved
        _run_dir.check_run_dir(out_dir, run, resume)
    kept = _kept_trainer(task, config, losses[kind.loss], params, say)
    trainer = kept.trainer
    if losses[kind.loss] is not None and out_dir is not None and resume:
        say("note: resuming with a custom loss; it must be the same function as before")

    devices = check_devices(devices)
    if devices > 1:
        if kind.one_device:
            raise ConfigError(f"task {task.name!r} is {kind.time}: {kind.one_device}")
        divisible(config.batch, devices, "batch", "--batch")
    if init is not None and _population(config) > 1:  # refused before anything compiles
        raise ConfigError(
            f"init starts from one controller; a population of {_population(config)} would start "
            "every member the same: leave population at 1"
        )
    with interrupts_deferred():  # one program (the keys too), not op by op
        ts, k_eval = _first_state(kept, config.seed, params)
    if init is None and _population(config) == 1 and not _checkpointed(out_dir, resume):
        init = _stroke_start(task, ts.controller, params, config.seed, say)
    if init is not None:
        ts = _started_from(ts, init)
    ts_sharding, whole = batch_placement(ts, devices, 1 if _population(config) > 1 else 0)
    best = None  # the controller of the best evaluation point so far

    out = None
    meta: dict[str, Any] = {
        "curve": [],
        "seconds_before": 0.0,
        "compile_seconds_before": 0.0,
        "best_index": 0,
    }
    if out_dir is not None:
        out = _run_dir.prepare_run_dir(out_dir, run, resume) if is_writer() else Path(out_dir)
        ckpt = out / CHECKPOINT_FILE
        if resume and ckpt.exists():
            like_best = trainer.pick(ts.controller, np.zeros(_population(config)))
            (ts, best), meta = load_checkpoint(ckpt, (ts, like_best))
            if not _finite(best):  # a damaged checkpoint: nothing is trained or written from it
                raise ModelFileError(
                    f"checkpoint {ckpt} holds a controller whose weights are not finite; it "
                    "cannot be resumed: start a new run in a new directory"
                )
            say(f"resuming {task.name} from update {int(ts.update)} ({ckpt})")

    if ts_sharding is not None:  # data parallel: simulations split, the rest replicated
        ts, params, k_eval = placer(ts_sharding)(ts), placer(whole)(params), placer(whole)(k_eval)
        best = best if best is None else placer(whole)(best)
    # Compile once, ahead of time (every compilation is timed apart by ``_timing``).
    # The evaluation first: a loss or a solve that fails on the untrained controller is
    # reported before the (longer) compilation of the training chunk.
    with interrupts_deferred():
        evaluate = kept.jitted("evaluate", trainer, whole)
        lowered = evaluate.lower(ts.controller, params, k_eval)
        evaluate = compiled_once(lowered, *compile_options(task, "evaluate"))

    chunks: list[tuple[int, Any]] = []  # (end update, compiled chunk) per stage still to run
    loop = TrainLoop(
        trainer,
        [config],
        params,
        evaluate,
        k_eval,
        chunks,
        say,
        meta=meta,
        best=best,
        t_start=t_start,
        log=log,
        on_point=on_point,
        diagnostics=Diagnostics(say, config.updates, int(ts.update), meta.get("warnings")),
        checkpoint=None if out is None else out / CHECKPOINT_FILE,
        compiled_before=compiled_before,
    )
    curve = loop.curves[0]
    if not curve:
        nan = np.full(1, math.nan)
        loop.record(ts, nan, nan, np.ones(1, bool))
        if not math.isfinite(curve[0]["eval_return"]):
            trainer.check_start(ts, params)
    elif loop.best is None:
        loop.best = trainer.pick(ts.controller, np.zeros(_population(config)))

    total = np.int32(config.updates)
    with interrupts_deferred():
        for i, (end, stage) in enumerate(kept.stages):
            if end > int(ts.update):
                chunk = kept.jitted(f"chunk {i}", stage, ts_sharding and (ts_sharding, whole))
                lowered = chunk.lower(ts, params, total)
                chunks.append((end, compiled_once(lowered, *compile_options(task, "chunk"))))

    ts = loop.run(ts)
    if log is not None:
        log.close()
    wall = loop.seconds()
    chosen = curve[loop.best_index[0]] if config.keep_best else curve[-1]
    if config.keep_best:
        controller = loop.best
    else:
        returns = loop.last_returns
        if returns is None:  # resumed after the last chunk: evaluate once more
            returns = np.asarray(evaluate(ts.controller, params, k_eval))
        controller = trainer.pick(ts.controller, returns)
    loop.diagnostics.finish(config, curve, chosen["update"])
    counts = trainer.counts(ts)
    compile_seconds = loop.compiled()
    seconds_before = loop.seconds_before
    metrics = {
        "task": task.name,
        "gym_id": task.gym_id,
        "seed": config.seed,
        "train_seconds": wall,
        "compile_seconds": float(meta["compile_seconds_before"]) + compile_seconds,
        # this call's part of the run's time (runs.save_run adds evaluate and write)
        "timings": {
            "compile": compile_seconds,
            "compile_programs": _timing.compiled_programs() - programs_before,
            "train": wall - (seconds_before + compile_seconds),
        },
        "eval_seconds_in_training": loop.eval_seconds,
        "callback_seconds": loop.callback_seconds,
        "updates": int(ts.update),
        **counts,
        "episode_length": trainer.episode_length,
        "stopped_early": bool(loop.stopped[0]),
        "returned_update": chosen["update"],
        "final_eval_return": chosen["eval_return"],
        "final_eval_return_std": chosen["eval_return_std"],
        "eval_episodes": getattr(config, "eval_episodes", 1),
        "num_parameters": trainer.num_parameters(controller),
        "curve": curve,
        "warnings": loop.diagnostics.warnings,
        "config": config.to_json(),
        "jax_version": jax.__version__,
        "device": str(jax.devices()[0].platform),
        "devices": devices,
        "processes": jax.process_count(),
    }
    if out is not None and is_writer():  # the controller, loadable at once
        io.write_json(
            out / "model.json", policies.model_document(task, controller, config, metrics)
        )
    return TrainResult(
        task=task,
        config=config,
        params=params,
        controller=controller,
        metrics=metrics,
        out_dir=None if out is None else Path(out),
    )


class TrainLoop(Loop):
    """``train``'s turn of the loop: one run (a controller or a population), its progress
    lines, TensorBoard ``log``, ``on_point`` callback, ``diagnostics`` and, where
    ``checkpoint`` names a file, a checkpoint after every chunk (``meta``: what it holds besides
    the state; a resumed run's curve, best index and times so far). The time spent in
    ``on_point`` is left out of the run's seconds and compile time."""

    def __init__(
        self,
        *args: Any,
        meta: dict[str, Any],
        log: Any,
        on_point: Callable[[dict[str, Any], MLPController], None] | None,
        diagnostics: Diagnostics,
        checkpoint: Path | None,
        compiled_before: float,
        **kwargs: Any,
    ) -> None:
        super().__init__(
            *args, curves=[list(meta["curve"])], best_index=[int(meta["best_index"])], **kwargs
        )
        self.config, self.meta, self.log, self.on_point = self.configs[0], meta, log, on_point
        self.diagnostics, self.checkpoint = diagnostics, checkpoint
        self.compiled_before, self.seconds_before = compiled_before, float(meta["seconds_before"])
        self.callback_seconds = self.callback_compile = 0.0

    def compiled(self) -> float:
        """This call's compilation so far (every program: ``_timing``)."""
        return _timing.compile_seconds() - self.compiled_before - self.callback_compile

    def lost(self, old: Any, new: Any, losses: list[np.ndarray], means: np.ndarray) -> np.ndarray:
        try:
            return super().lost(old, new, losses, means)
        except TrainingDiverged as e:
            kept = self.checkpoint is not None and self.checkpoint.exists()
            where = f"; the last good checkpoint is in {self.checkpoint.parent}" if kept else ""
            raise type(e)(f"{e}{where}") from None

    def seconds(self) -> float:
        return self.seconds_before + super().seconds() - self.callback_seconds

    def points_made(self, ts: Any, returns: np.ndarray, points: list[dict | None]) -> None:
        point = points[0]
        if self.log is not None:
            self.log.point(point)
        self.say(_progress_line(point, self.config.updates))
        if self.on_point is not None:
            t_cb, c_cb = time.perf_counter(), _timing.compile_seconds()
            self.on_point(point, self.trainer.pick(ts.controller, returns))
            self.callback_seconds += time.perf_counter() - t_cb
            self.callback_compile += _timing.compile_seconds() - c_cb

    def chunk_done(
        self, updates: np.ndarray, done: np.ndarray, losses: list[np.ndarray], grads: list
    ) -> None:
        self.diagnostics.after_chunk(losses[0], grads[0], self.config.learning_rate)
        if self.log is not None:
            first = int(updates[0])
            rates = learning_rates(self.config, first, int(done[0]))
            self.log.updates(first, losses[0], grads[0], rates)

    def saved(self, ts: Any) -> None:
        if self.checkpoint is None:
            return
        whole_state = gathered((ts, self.best))  # every process takes part; process 0 writes
        if is_writer():
            meta = {
                "curve": self.curves[0],
                "best_index": int(self.best_index[0]),
                "seconds_before": self.seconds(),
                "compile_seconds_before": float(self.meta["compile_seconds_before"])
                + self.compiled(),
                "warnings": self.diagnostics.warnings,
            }
            # an interrupt inside np.savez leaves its ZipFile open, whose finaliser then prints
            # a traceback: the signal waits for the whole write (atomic either way)
            with interrupts_deferred():
                save_checkpoint(self.checkpoint, whole_state, meta)


def _finite(tree: PyTree) -> bool:
    """Whether every floating-point array of ``tree`` is finite."""
    leaves = jax.tree.leaves(eqx.filter(tree, eqx.is_inexact_array))
    return all(bool(np.all(np.isfinite(np.asarray(x)))) for x in leaves)


def _checkpointed(out_dir: str | Path | None, resume: bool) -> bool:
    """Whether this run continues from a checkpoint (which holds its controller)."""
    return resume and out_dir is not None and (Path(out_dir) / CHECKPOINT_FILE).exists()


def _stroke_start(
    task: AnyTask, controller: MLPController, params: PyTree, seed: int, say: Any
) -> MLPController | None:
    """The controller fitted to the task's open-loop stroke (``_stroke``), if it declares one."""
    drive = stroke(task)
    if drive is None:
        return None
    _check_stroke(task, drive)
    t0 = time.perf_counter()
    key = jax.random.fold_in(jax.random.PRNGKey(seed), 1)  # apart from the training's keys
    fitted, error = imitate(task, controller, params, key, drive)
    say(
        f"starting from the task's stroke (period {drive.period:g} steps), fitted in "
        f"{time.perf_counter() - t0:.0f} s (mean squared action error {error:.2g})"
    )
    return fitted


def _check_stroke(task: AnyTask, drive: Any) -> None:
    """Refuse, in one line, a stroke that ``imitate`` cannot play on ``task``."""
    where = f"task {task.name!r}'s stroke()"
    if not isinstance(task, Task):
        raise ConfigError(f"{where}: only a discrete-time task can start from a stroke")
    if not isinstance(drive, Stroke):
        raise ConfigError(f"{where} returned {drive!r}: return a diffcontrol.tasks.Stroke")
    try:
        period = float(drive.period)
        amplitude, phase = (np.asarray(v, float).reshape(-1) for v in drive[1:])
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: {drive}: give numbers") from None
    if not (amplitude.size == phase.size == task.action_size):
        raise ConfigError(
            f"{where} has {amplitude.size} amplitudes and {phase.size} phases: give one of "
            f"each per action ({task.action_size})"
        )
    if not (np.isfinite([period, *amplitude, *phase]).all() and period > 0):
        raise ConfigError(f"{where}: {drive}: give a positive period and finite numbers")


def _started_from(ts: Any, init: Any) -> Any:
    """The first training state ``ts`` (of one controller) with ``init`` in place of its random
    controller (the optimiser's state is that of fresh weights either way: zero moments).

    Raises:
        ConfigError: a controller whose network is not the one this run makes (another size,
            activation or head).
    """
    fresh, static = eqx.partition(ts.controller, eqx.is_array)
    given = eqx.filter(init, eqx.is_array)
    new, old = jax.tree.leaves(given), jax.tree.leaves(fresh)
    # the ODE trainer's controller has a leading population axis (of 1) on every array
    lead = old[0].ndim - new[0].ndim if new and old else 0
    fits = (  # the network, not its training-only slope floor (_network)
        isinstance(init, MLPController)
        and _network(init) == _network(ts.controller)
        and len(new) == len(old)
        and all(np.shape(a) == b.shape[lead:] for a, b in zip(new, old, strict=True))
    )
    if not fits:
        raise ConfigError(
            f"the controller to start from ({_network(init)}) is not the network this run "
            f"makes ({_network(ts.controller)}); use its hidden sizes, activation and head "
            "(--hidden, --activation, --head)"
        )
    arrays = jax.tree.unflatten(
        jax.tree.structure(fresh),
        [jnp.broadcast_to(jnp.asarray(a, b.dtype), b.shape) for a, b in zip(new, old)],
    )
    return eqx.tree_at(lambda t: t.controller, ts, eqx.combine(arrays, static))


def _network(controller: Any) -> str:
    """A controller's layer widths, activation and head, in words."""
    if not isinstance(controller, MLPController):
        return f"a {type(controller).__name__}, not an MLPController"
    shapes = [layer.weight.shape[-2:] for layer in controller.layers]
    widths = "x".join(str(n) for n in (shapes[0][1], *(out for out, _ in shapes)))
    return f"layers {widths}, {controller.activation} activation, {controller.head} head"


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) and SIGTERM while XLA compiles and deliver them as
    ``KeyboardInterrupt`` once the compiler has returned: an interrupt inside the compiler can
    crash the process instead of ending it with the resume hint. Only the main thread can take signals; elsewhere this
    does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    # SIGTERM takes Ctrl-C's path (the CLI's); a signal the process ignores stays ignored.
    signums = [s for s in (signal.SIGINT, signal.SIGTERM) if signal.getsignal(s) != signal.SIG_IGN]
    previous = {s: signal.signal(s, lambda signum, frame: pending.append(signum)) for s in signums}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if pending:
        if signal.SIGTERM in pending and previous[signal.SIGTERM] in (signal.SIG_DFL, None):
            signal.raise_signal(signal.SIGTERM)  # no handler of ours: end as SIGTERM would
        raise KeyboardInterrupt


_CONTINUOUS_HEADS = ("linear", "tanh", "sigmoid")


def _check_head(task: AnyTask, config: Any) -> None:
    """A head override must make the same kind of action as the task's own head: a discrete
    head cannot replace a continuous one (or the reverse), and a bounded one needs bounds. A
    slope floor needs a tanh or sigmoid head."""
    head, floor = config.head, getattr(config, "head_slope_floor", 0.0)
    if floor and (head or task.action_head) not in ("tanh", "sigmoid"):
        raise ConfigError(
            f"head_slope_floor={floor} (--head-slope-floor) is for a tanh or sigmoid head, and "
            f"this run's head is {head or task.action_head!r}; leave it at 0"
        )
    if not head or head == task.action_head:
        return
    own_continuous = task.action_head in _CONTINUOUS_HEADS
    if head not in _CONTINUOUS_HEADS or not own_continuous:
        raise ConfigError(
            f"head {head!r} does not fit task {task.name!r}, whose actions come from its "
            f"{task.action_head!r} head; leave --head empty"
            + ("" if not own_continuous else " or choose linear, tanh or sigmoid")
        )
    if head != "linear" and (task.action_low is None or task.action_high is None):
        raise ConfigError(
            f"head {head!r} needs action bounds, and task {task.name!r} has none; use linear"
        )


def _population(config: Any) -> int:
    """How many controllers a run trains side by side (1 for discrete-time runs)."""
    return getattr(config, "population", 1)
