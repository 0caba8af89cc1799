"""The thin Python driver around the jitted chunks: progress, evaluation points, checkpoints."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PyTree

from .. import io
from ..config import TrainConfig
from ..controllers import MLPController
from ..errors import ConfigError, DiffcontrolError
from ..tasks import StepLoss, Task
from ._bptt import TrainState, make_trainer

CHECKPOINT_FILE = "checkpoint.npz"


class TrainingDiverged(DiffcontrolError):
    """The loss or the weights became non-finite; the last good checkpoint is kept."""


@dataclasses.dataclass
class TrainResult:
    """What ``train`` returns: the trained controller and everything measured on the way."""

    task: Task
    config: TrainConfig
    params: PyTree
    controller: MLPController
    metrics: dict[str, Any]

    @property
    def curve(self) -> list[dict[str, Any]]:
        """The learning curve: one dict per evaluation point."""
        return self.metrics["curve"]


def task_params(task: Task, overrides: tuple[tuple[str, float], ...] = ()) -> PyTree:
    """The task's nominal parameters with ``overrides`` applied, as JAX arrays."""
    params = task.default_params()
    for name, value in overrides:
        if not hasattr(params, name):
            fields = [f.name for f in dataclasses.fields(params)]
            raise ConfigError(
                f"task {task.name!r} has no parameter {name!r}; its parameters are {', '.join(fields)}"
            )
        params = eqx.tree_at(lambda p, n=name: getattr(p, n), params, value)
    return jax.tree.map(lambda x: jnp.asarray(x, dtype=float), params)


def resolve_config(task: Task, recipe: str | None = None, **overrides: Any) -> TrainConfig:
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
    ret = point["eval_return"]
    return (
        f"[{pct:5.1f}%] update {point['update']:>5}/{total}  "
        f"episodes {point['simulated_episodes']:8.1f}  loss {point['loss']:10.4g}  "
        f"eval return {ret:9.2f}  {point['seconds']:6.1f} s"
    )


def train(
    task: Task,
    config: TrainConfig | None = None,
    *,
    out_dir: str | Path | None = None,
    resume: bool = False,
    step_loss: StepLoss | None = None,
    progress: Callable[[str], None] | None = None,
    on_point: Callable[[dict[str, Any], MLPController], None] | None = None,
) -> TrainResult:
    """Train a controller for ``task`` by truncated BPTT through its simulator.

    Args:
        task: a task from ``diffcontrol.make``.
        config: the settings; ``task.default_config()`` when omitted.
        out_dir: if given, ``run.json`` and a checkpoint after every chunk are written there,
            so an interrupted run can continue with ``resume=True``.
        resume: continue the run in ``out_dir`` from its last checkpoint.
        step_loss: a user-supplied training loss ``f(params, state, action, next_state,
            reward) -> scalar`` that replaces the task's built-in one.
        progress: called with one human-readable line per evaluation point.
        on_point: called with each evaluation point (the dict that joins the curve) and the
            controller at that point, e.g. to evaluate it elsewhere. The time spent in it is
            left out of every ``seconds`` and of ``train_seconds`` (and reported as
            ``callback_seconds``); it is not saved in checkpoints, so a resumed run calls it
            only for the points after the resume.

    Returns:
        A ``TrainResult`` whose controller is the one of the best evaluation point when
        ``config.keep_best`` (the default), else the last; ``metrics`` holds
        ``train_seconds`` (wall clock, compilation and evaluation included), ``compile_seconds``, ``simulated_steps``,
        ``simulated_episodes`` (in the task's standard episode length), the ``curve``, and
        ``returned_update`` with ``final_eval_return`` (the returned controller's).

    Raises:
        ConfigError, RunDirectoryError, ModelFileError: bad settings or directories.
        TrainingDiverged: the loss became non-finite (lower the learning rate or clip).
    """
    t_start = time.perf_counter()
    config = config or task.default_config()
    say = progress or (lambda line: None)
    params = task_params(task, config.params)
    trainer = make_trainer(task, config, step_loss)
    if step_loss is not None and out_dir is not None and resume:
        say("note: resuming with a custom step loss; it must be the same function as before")

    key = jax.random.PRNGKey(config.seed)
    k_train, k_eval = jax.random.split(key)
    ts = trainer.init(k_train, params)
    best = ts.controller  # the controller of the best evaluation point so far
    steps_per_update = config.window * config.batch

    out = None
    meta: dict[str, Any] = {
        "curve": [],
        "seconds_before": 0.0,
        "compile_seconds_before": 0.0,
        "best_index": 0,
    }
    if out_dir is not None:
        run = {"format": "diffcontrol-run", "task": task.name, "config": config.to_json()}
        out = io.prepare_run_dir(out_dir, run, resume)
        ckpt = out / CHECKPOINT_FILE
        if resume and ckpt.exists():
            (ts, best), meta = io.load_checkpoint(ckpt, (ts, ts.controller))
            say(f"resuming {task.name} from update {int(ts.update)} ({ckpt})")

    # Compile once, ahead of time, so that compile time is measured apart from training time.
    t0 = time.perf_counter()
    total = jnp.asarray(config.updates, jnp.int32)
    chunk = jax.jit(trainer.chunk).lower(ts, params, total).compile()
    evaluate = jax.jit(trainer.evaluate).lower(ts.controller, params, k_eval).compile()
    compile_seconds = time.perf_counter() - t0

    curve: list[dict[str, Any]] = list(meta["curve"])
    seconds_before = float(meta["seconds_before"])
    eval_seconds = 0.0
    callback_seconds = 0.0  # time spent in on_point, left out of the training time

    best_index = int(meta["best_index"])

    def record(ts: TrainState, loss: float, grad_norm: float) -> dict[str, Any]:
        nonlocal eval_seconds, best, best_index, callback_seconds
        t_eval = time.perf_counter()
        returns = np.asarray(evaluate(ts.controller, params, k_eval))
        eval_seconds += time.perf_counter() - t_eval
        update = int(ts.update)
        steps = update * steps_per_update
        n_fin = int(ts.finished_episodes)
        point = {
            "update": update,
            "simulated_steps": steps,
            "simulated_episodes": steps / task.episode_length,
            "seconds": seconds_before + time.perf_counter() - t_start - callback_seconds,
            "loss": loss,
            "grad_norm": grad_norm,
            "eval_return": float(returns.mean()),
            "eval_return_std": float(returns.std()),
            "train_episodes_finished": n_fin,
            "train_return_mean": float(ts.finished_return_sum) / n_fin if n_fin else math.nan,
        }
        curve.append(point)
        # ">=": among equal returns (CartPole's 500s) the later, longer-trained controller.
        so_far = curve[best_index]["eval_return"]
        if len(curve) == 1 or math.isnan(so_far) or point["eval_return"] >= so_far:
            best, best_index = ts.controller, len(curve) - 1
        say(_progress_line(point, config.updates))
        if on_point is not None:
            t_cb = time.perf_counter()
            on_point(point, ts.controller)
            callback_seconds += time.perf_counter() - t_cb
        return point

    if not curve:
        record(ts, math.nan, math.nan)

    stopped_early = False
    target = config.target_return
    while int(ts.update) < config.updates:
        if not math.isnan(target) and curve and curve[-1]["eval_return"] >= target:
            stopped_early = True
            break
        new_ts, stats = chunk(ts, params, total)
        done = int(new_ts.update - ts.update)  # updates past the budget were skipped
        losses = np.asarray(stats.loss)[:done]
        weights = eqx.filter(new_ts.controller, eqx.is_inexact_array)
        weights_ok = all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree.leaves(weights))
        if not (np.all(np.isfinite(losses)) and weights_ok):
            bad = int(ts.update) + int(np.argmax(~np.isfinite(losses))) + 1
            raise TrainingDiverged(
                f"training diverged near update {bad}: the loss or the weights became non-finite; "
                f"lower --learning-rate (now {config.learning_rate:g}) or set --grad-clip "
                f"(now {config.grad_clip:g})"
                + (f"; the last good checkpoint is in {out}" if out else "")
            )
        ts = new_ts
        record(ts, float(np.mean(losses)), float(np.mean(np.asarray(stats.grad_norm)[:done])))
        if out is not None:
            io.save_checkpoint(
                out / CHECKPOINT_FILE,
                (ts, best),
                {
                    "curve": curve,
                    "best_index": best_index,
                    "seconds_before": seconds_before
                    + time.perf_counter()
                    - t_start
                    - callback_seconds,
                    "compile_seconds_before": float(meta["compile_seconds_before"])
                    + compile_seconds,
                },
            )

    updates_done = int(ts.update)
    steps = updates_done * steps_per_update
    wall = seconds_before + time.perf_counter() - t_start - callback_seconds
    chosen = curve[best_index] if config.keep_best else curve[-1]
    metrics = {
        "task": task.name,
        "gym_id": task.gym_id,
        "seed": config.seed,
        "train_seconds": wall,
        "compile_seconds": float(meta["compile_seconds_before"]) + compile_seconds,
        "eval_seconds_in_training": eval_seconds,
        "callback_seconds": callback_seconds,
        "updates": updates_done,
        "simulated_steps": steps,
        "simulated_episodes": steps / task.episode_length,
        "episode_length": task.episode_length,
        "stopped_early": stopped_early,
        "returned_update": chosen["update"],
        "final_eval_return": chosen["eval_return"],
        "final_eval_return_std": chosen["eval_return_std"],
        "eval_episodes": config.eval_episodes,
        "num_parameters": ts.controller.num_parameters,
        "curve": curve,
        "config": config.to_json(),
        "jax_version": jax.__version__,
        "device": str(jax.devices()[0].platform),
    }
    controller = best if config.keep_best else ts.controller
    return TrainResult(
        task=task, config=config, params=params, controller=controller, metrics=metrics
    )
