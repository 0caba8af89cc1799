"""Windowed backpropagation through time: the pure, jitted part of the trainer.

One *update* runs every simulation in the batch forward ``window`` steps from its carried
state, differentiates the mean step loss through the simulator and the controller, clips the
gradient, and takes one optimiser step. The simulator states come out of the window as plain
values, so the next window starts from them without their history: truncated BPTT, written
out rather than hidden in a ``stop_gradient``. A *chunk* is ``lax.scan`` over a fixed number of
updates under one ``jit``; the Python driver calls the same compiled chunk again and again.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float, Int, PRNGKeyArray, PyTree

from .. import optimal
from ..config import MAX_VALUE_GRID, TrainConfig
from ..controllers import MLPController
from ..errors import ConfigError, TrainingDiverged
from ..rollout import batch_returns
from ..tasks import StepLoss, Task, controller_kwargs, task_params
from ._interface import TrainerKind, register_trainer


class TrainState(eqx.Module):
    """Everything a training run carries from one update to the next (and checkpoints)."""

    controller: MLPController
    opt_state: PyTree
    env_state: Float[Array, "batch state"]
    env_time: Int[Array, " batch"]
    episode_return: Float[Array, " batch"]
    key: PRNGKeyArray
    update: Int[Array, ""]
    finished_episodes: Int[Array, ""]
    finished_return_sum: Float[Array, ""]


class UpdateStats(eqx.Module):
    """Per-update diagnostics, stacked over a chunk."""

    loss: Float[Array, ""]
    grad_norm: Float[Array, ""]


def learning_rate_schedule(
    config: TrainConfig, learning_rate: Any = None
) -> optax.ScalarOrSchedule:
    """The configured learning-rate schedule (a float for ``constant``): the learning rate of
    update ``u + 1`` is ``schedule(u)``. ``learning_rate`` (default ``config.learning_rate``)
    may be a traced value: a sweep builds the same schedule with one learning rate per member.
    """
    lr = config.learning_rate if learning_rate is None else learning_rate
    final = lr * config.lr_final_fraction
    if config.lr_schedule == "constant":
        return lr
    if config.lr_schedule == "cosine":
        return optax.cosine_decay_schedule(lr, config.updates, alpha=config.lr_final_fraction)
    warmup = max(1, config.updates // 20)
    steps = max(config.updates, warmup + 1)
    if isinstance(lr, int | float):
        return optax.warmup_cosine_decay_schedule(0.0, lr, warmup, steps, end_value=final)
    # traced (a sweep's): optax divides by the peak in Python, so scale a unit one
    unit = optax.warmup_cosine_decay_schedule(
        0.0, 1.0, warmup, steps, end_value=config.lr_final_fraction
    )
    return lambda count: lr * unit(count)


def make_optimizer(config: TrainConfig, learning_rate: Any = None) -> optax.GradientTransformation:
    """Adam with the configured schedule (``learning_rate_schedule``), after optional
    global-norm gradient clipping.

    ``learning_rate`` (default ``config.learning_rate``) may be a traced value: a sweep builds
    the same chain inside ``optax.inject_hyperparams`` with one learning rate per member.
    """
    schedule = learning_rate_schedule(config, learning_rate)
    parts = [optax.clip_by_global_norm(config.grad_clip)] if config.grad_clip > 0 else []
    return optax.chain(*parts, optax.adam(schedule))


class Trainer(eqx.Module):
    """The pure functions of one training configuration (built once, compiled once)."""

    task: Task = eqx.field(static=True)
    config: TrainConfig = eqx.field(static=True)
    step_loss: StepLoss = eqx.field(static=True)
    optimizer: optax.GradientTransformation = eqx.field(static=True)
    horizon: int = eqx.field(static=True)
    window: int = eqx.field(static=True)
    """The simulated steps per update of this trainer's chunks (``config.window``, or
    ``config.final_window`` for the last stage of a window curriculum: ``stages``)."""
    value: Any = eqx.field(static=True, default=None)
    """The windows' terminal value (``config.value_grid``): the grid dynamic program's
    ``ValueTable`` (``V_0`` only, or every ``V_t`` with ``config.value_time``) in a
    ``Constant``; or ``None``."""

    def __check_init__(self) -> None:
        if self.config.value_grid and self.value is None:
            raise ConfigError(
                f"value_grid={self.config.value_grid} but the trainer was given no terminal "
                "value; build it with make_trainer (or value=terminal_value(...))"
            )

    def init(self, key: PRNGKeyArray, params: PyTree) -> TrainState:
        """A fresh training state: a random controller and ``batch`` reset simulations."""
        k_ctrl, k_env, k_run = jax.random.split(key, 3)
        cfg = self.config
        kwargs = controller_kwargs(self.task)
        if cfg.head:
            kwargs["head"] = cfg.head
        controller = MLPController(
            k_ctrl,
            hidden=cfg.hidden,
            activation=cfg.activation,
            head_floor=cfg.head_slope_floor,
            **kwargs,
        )
        env_state = jax.vmap(lambda k: self.task.reset(k, params))(
            jax.random.split(k_env, cfg.batch)
        )
        zero = jnp.zeros((), jnp.int32)
        return TrainState(
            controller=controller,
            opt_state=self.optimizer.init(eqx.filter(controller, eqx.is_inexact_array)),
            env_state=env_state,
            env_time=jnp.zeros((cfg.batch,), jnp.int32),
            episode_return=jnp.zeros((cfg.batch,), env_state.dtype),
            key=k_run,
            update=zero,
            finished_episodes=zero,
            finished_return_sum=jnp.zeros((), env_state.dtype),
        )

    def horizon_at(self, update: Array) -> Array | int:
        """The training episodes' length (steps) at ``update``: the curriculum's, growing
        linearly from ``curriculum_start`` of the horizon, or the horizon itself."""
        cfg = self.config
        if cfg.curriculum_start >= 1:
            return self.horizon
        growth = max(1.0, cfg.curriculum_fraction * cfg.updates)
        frac = cfg.curriculum_start + (1 - cfg.curriculum_start) * update / growth
        return jnp.maximum(1, jnp.ceil(self.horizon * jnp.minimum(1.0, frac))).astype(jnp.int32)

    def window_loss(
        self, controller, params, env_state, env_time, episode_return, keys, horizon=None
    ):
        """Mean step loss over one window and the batch, and the carried-out states.

        With a terminal value (``value``), each simulation's window loss also has minus the
        value of the state it leaves the window in, divided by the window's steps (none when
        its episode ended at the window's last step: the return stops there)."""
        task, step_loss = self.task, self.step_loss
        horizon = self.horizon if horizon is None else horizon

        def one_env(state, time, ret, env_keys):
            def body(carry, key):
                state, time, ret = carry
                action = controller(task.observe(state))
                next_state, reward, term = task.step(params, state, action)
                loss = step_loss(params, state, action, next_state, reward)
                time, ret = time + 1, ret + reward
                done = term | (time >= horizon)
                # An explicit restart: the new episode's state does not depend on the old one.
                carried = jnp.where(done, task.reset(key, params), next_state)
                out = (loss, done, ret)
                return (carried, jnp.where(done, 0, time), jnp.where(done, 0.0, ret)), out

            carry, (losses, done, rets) = jax.lax.scan(body, (state, time, ret), env_keys)
            loss = jnp.mean(losses)
            if self.value is not None:  # minus the return to go of the state left, per step
                # V_t with the steps the episode has left: ``horizon - t`` of its (under the
                # curriculum, shorter) horizon, which is V at ``t + self.horizon - horizon``
                t = carry[1] + (self.horizon - horizon) if self.config.value_time else 0
                to_go = jnp.where(done[-1], 0.0, self.value.table.value(t, carry[0]))
                loss = loss - to_go / losses.shape[0]
            return carry, (loss, jnp.sum(done), jnp.sum(jnp.where(done, rets, 0.0)))

        carry, (losses, n_done, ret_sum) = jax.vmap(one_env, in_axes=(0, 0, 0, 1))(
            env_state, env_time, episode_return, keys
        )
        return jnp.mean(losses), (carry, jnp.sum(n_done), jnp.sum(ret_sum))

    def update(self, ts: TrainState, params: PyTree) -> tuple[TrainState, UpdateStats]:
        """One truncated-BPTT update (one window)."""
        cfg = self.config
        key, k_win = jax.random.split(ts.key)
        keys = jax.random.split(k_win, (self.window, cfg.batch))

        grad_fn = eqx.filter_value_and_grad(self.window_loss, has_aux=True)
        (loss, (carry, n_done, ret_sum)), grads = grad_fn(
            ts.controller,
            params,
            ts.env_state,
            ts.env_time,
            ts.episode_return,
            keys,
            self.horizon_at(ts.update),
        )
        updates, opt_state = self.optimizer.update(
            grads, ts.opt_state, eqx.filter(ts.controller, eqx.is_inexact_array)
        )
        controller = eqx.apply_updates(ts.controller, updates)
        env_state, env_time, episode_return = carry
        new = TrainState(
            controller=controller,
            opt_state=opt_state,
            env_state=env_state,
            env_time=env_time,
            episode_return=episode_return,
            key=key,
            update=ts.update + 1,
            finished_episodes=ts.finished_episodes + n_done.astype(jnp.int32),
            finished_return_sum=ts.finished_return_sum + ret_sum,
        )
        return new, UpdateStats(loss=loss, grad_norm=optax.tree_utils.tree_norm(grads))

    def chunk(self, ts: TrainState, params: PyTree, total_updates: Array):
        """``eval_every`` updates under one ``lax.scan``; updates past ``total_updates`` are skipped.

        Skipping (rather than a shorter last chunk) keeps one compiled program for the run.
        """

        def body(ts, _):
            def skip(ts, params):
                nan = jnp.full((), jnp.nan, ts.finished_return_sum.dtype)
                return ts, UpdateStats(loss=nan, grad_norm=nan)

            return jax.lax.cond(ts.update < total_updates, self.update, skip, ts, params)

        return jax.lax.scan(body, ts, None, length=self.config.eval_every)

    def evaluate(self, controller: MLPController, params: PyTree, key: PRNGKeyArray) -> Array:
        """Returns of ``eval_episodes`` standard-length episodes in the simulator."""
        keys = jax.random.split(key, self.config.eval_episodes)
        return batch_returns(self.task, params, controller, keys, self.task.episode_length)

    # --- the driver's hooks (plain Python, between chunks) --------------------------------

    @property
    def episode_length(self) -> int:
        return self.task.episode_length

    def summarize(self, returns: np.ndarray) -> tuple[float, float]:
        """Mean and spread of the evaluation episodes' returns."""
        return float(np.mean(returns)), float(np.std(returns))

    def pick(self, controller: MLPController, returns: np.ndarray) -> MLPController:
        """The controller to keep for this evaluation point (there is only one)."""
        return controller

    def stages(self) -> list[tuple[int, Trainer]]:
        """The run's stages in order, as ``(end update, trainer)``: one, or two when the
        window curriculum (``config.final_window``) switches to longer windows."""
        cfg = self.config
        switch = cfg.final_window_start
        if switch >= cfg.updates:
            return [(cfg.updates, self)]
        long = dataclasses.replace(self, window=cfg.final_window)
        return [(switch, self), (cfg.updates, long)] if switch > 0 else [(cfg.updates, long)]

    def counts(self, ts: TrainState) -> dict[str, Any]:
        steps = self.config.simulated_steps(int(ts.update))
        return {"simulated_steps": steps, "simulated_episodes": steps / self.task.episode_length}

    def point_extras(self, ts: TrainState, returns: np.ndarray) -> dict[str, Any]:
        n_fin = int(ts.finished_episodes)
        return {
            "train_episodes_finished": n_fin,
            "train_return_mean": float(ts.finished_return_sum) / n_fin if n_fin else math.nan,
        }

    def check(self, old: TrainState, new: TrainState, losses: np.ndarray) -> list[str]:
        """Raise ``TrainingDiverged`` if the loss or the weights became non-finite."""
        weights = eqx.filter(new.controller, eqx.is_inexact_array)  # NumPy: nothing compiled
        weights_ok = all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(weights))
        if not (np.all(np.isfinite(losses)) and weights_ok):
            bad = int(old.update) + int(np.argmax(~np.isfinite(losses))) + 1
            cfg = self.config
            raise TrainingDiverged(
                f"training diverged near update {bad}: the loss or the weights became "
                f"non-finite; lower --learning-rate (now {cfg.learning_rate:g}) or set "
                f"--grad-clip (now {cfg.grad_clip:g})"
            )
        return []

    def num_parameters(self, controller: MLPController) -> int:
        return controller.num_parameters

    def check_start(self, ts: Any, params: PyTree) -> None:
        """Nothing to add: a non-finite first evaluation shows on the curve and in ``check``."""


class PopulationState(eqx.Module):
    """The training states of ``population`` controllers (a leading axis on every array of
    ``members``), with the shared update count."""

    members: TrainState
    update: Int[Array, ""]

    @property
    def controller(self) -> MLPController:
        """The members' controllers, stacked."""
        return self.members.controller


class PopulationTrainer(eqx.Module):
    """``population`` independent BPTT runs side by side under ``vmap`` (restarts against
    local optima in one compiled program). Each member has its own initialisation, batch of
    simulations and optimiser; at every evaluation point the member with the best
    in-simulator return is the run's controller."""

    base: Trainer
    population: int = eqx.field(static=True)

    @property
    def config(self) -> TrainConfig:
        return self.base.config

    @property
    def episode_length(self) -> int:
        return self.base.episode_length

    def stages(self) -> list[tuple[int, PopulationTrainer]]:
        """The base trainer's stages (``Trainer.stages``), each for the whole population."""
        return [(end, PopulationTrainer(t, self.population)) for end, t in self.base.stages()]

    def init(self, key: PRNGKeyArray, params: PyTree) -> PopulationState:
        keys = jax.random.split(key, self.population)
        members = eqx.filter_vmap(self.base.init, in_axes=(0, None))(keys, params)
        return PopulationState(members=members, update=jnp.zeros((), jnp.int32))

    def chunk(self, ts: PopulationState, params: PyTree, total_updates: Array):
        members, stats = eqx.filter_vmap(self.base.chunk, in_axes=(0, None, None))(
            ts.members, params, total_updates
        )
        # every member takes the same number of updates
        update = jnp.max(members.update)
        stats = UpdateStats(
            loss=jnp.nanmean(stats.loss, axis=0), grad_norm=jnp.nanmean(stats.grad_norm, axis=0)
        )
        return PopulationState(members=members, update=update), stats

    def evaluate(self, controllers: MLPController, params: PyTree, key: PRNGKeyArray) -> Array:
        """Each member's evaluation returns on the same starts: ``[population, episodes]``."""
        return eqx.filter_vmap(self.base.evaluate, in_axes=(0, None, None))(
            controllers, params, key
        )

    def _best(self, returns: np.ndarray) -> int:
        means = returns if returns.ndim == 1 else np.mean(returns, axis=-1)
        means = np.where(np.isfinite(means), means, -np.inf)
        return int(np.argmax(means))

    def summarize(self, returns: np.ndarray) -> tuple[float, float]:
        """Mean and spread of the best member's returns."""
        return self.base.summarize(returns[self._best(returns)])

    def pick(self, controllers: MLPController, returns: np.ndarray) -> MLPController:
        """The best member's controller."""
        i = self._best(np.asarray(returns))
        # Sliced by NumPy and placed back: no program compiled per weight array.
        return jax.tree.map(
            lambda x: jax.device_put(np.asarray(x)[i]) if eqx.is_array(x) else x, controllers
        )

    def counts(self, ts: PopulationState) -> dict[str, Any]:
        one = self.base.counts(ts)  # reads ts.update only
        steps = one["simulated_steps"] * self.population
        return {"simulated_steps": steps, "simulated_episodes": steps / self.episode_length}

    def point_extras(self, ts: PopulationState, returns: np.ndarray) -> dict[str, Any]:
        n_fin = int(np.sum(ts.members.finished_episodes))
        total = float(np.sum(ts.members.finished_return_sum))
        return {
            "train_episodes_finished": n_fin,
            "train_return_mean": total / n_fin if n_fin else math.nan,
            "best_member": self._best(np.asarray(returns)),
        }

    def check(self, old: PopulationState, new: PopulationState, losses: np.ndarray) -> list[str]:
        """Raise ``TrainingDiverged`` when every member diverged; a note for each that did."""
        weights = eqx.filter(new.controller, eqx.is_inexact_array)
        finite = np.ones(self.population, bool)
        for leaf in jax.tree.leaves(weights):  # by NumPy: no programs compiled for the check
            finite &= np.isfinite(np.asarray(leaf).reshape(self.population, -1)).all(axis=1)
        if not finite.any():
            return self.base.check(old, new, np.full_like(losses, np.nan))
        was = eqx.filter(old.controller, eqx.is_inexact_array)
        before = np.ones(self.population, bool)
        for leaf in jax.tree.leaves(was):
            before &= np.isfinite(np.asarray(leaf).reshape(self.population, -1)).all(axis=1)
        lost = np.flatnonzero(before & ~finite)
        return [f"population member {i} diverged; the others train on" for i in lost]

    def num_parameters(self, controller: MLPController) -> int:
        return controller.num_parameters

    def check_start(self, ts: Any, params: PyTree) -> None:
        """Nothing to add: a non-finite first evaluation shows on the curve and in ``check``."""


def builtin_loss_name(task: Any, requested: str, argument: str) -> str:
    """The built-in loss a run uses: ``requested`` (``config.loss``), else the task's first.

    Raises:
        ConfigError: the task has no built-in losses (pass ``argument`` to ``train``), or
            none called ``requested``.
    """
    if not task.losses:
        raise ConfigError(
            f"task {task.name!r} has no built-in losses; pass one to "
            f"diffcontrol.train(task, {argument}=...)"
        )
    name = requested or task.losses[0]
    if name not in task.losses:
        raise ConfigError(
            f"unknown loss {name!r} for task {task.name!r}; choose one of {', '.join(task.losses)}"
        )
    return name


class Constant:
    """A value a trainer's programs hold as a constant: hashed and compared by identity, so
    that a trainer holding arrays stays a static, hashable part of its jitted methods."""

    def __init__(self, table: Any) -> None:
        self.table = table


MAX_HELD = 2**25
"""The most values a training program may hold as its terminal value (``value_time``: every
step's grid, a constant of the compiled program and of its cache entry): 128 MB."""


def check_value_grid(task: Any, config: TrainConfig, params: PyTree = None) -> None:
    """Refuse a terminal value (``config.value_grid``) the task cannot have: no state grid, no
    action bounds, more grid points than ``MAX_VALUE_GRID`` squared, or a table over the
    training horizon larger than ``optimal.MAX_TABLE`` values (``MAX_HELD`` with ``value_time``);
    nothing solved.

    Raises:
        ConfigError: one line, naming the value and the way out.
    """
    import math

    points = config.value_grid
    params = task.default_params() if params is None else params
    try:
        axes, sizes = optimal._check_grid(task, params, points, 2)
        optimal._action_grid(task, 2)
    except ConfigError as e:
        raise ConfigError(
            f"value_grid={points} needs the task's grid optimum, but {e}; train without it "
            "(value_grid=0, --value-grid 0)"
        ) from None
    total, most = math.prod(sizes), MAX_VALUE_GRID**2
    if total > most:
        each = int(most ** (1 / len(axes)))
        raise ConfigError(
            f"value_grid={points} makes {total:,} grid points over the task's {len(axes)} state "
            f"axes, more than {most:,}; choose at most {each} points per axis"
        )
    steps = (config.horizon or task.episode_length) + 1
    limit = MAX_HELD if config.value_time else optimal.MAX_TABLE
    what = "held by the training program" if config.value_time else "solved"
    if steps * total > limit:
        each = int((limit / steps) ** (1 / len(axes)))
        raise ConfigError(
            f"value_grid={points} over {steps - 1} steps makes a table of {steps * total:,} "
            f"values to be {what}, more than {limit:,}; choose at most {each} points per axis"
            + (" or leave value_time off" if config.value_time else " or a shorter horizon")
        )


def terminal_value(
    task: Task,
    config: TrainConfig,
    params: PyTree,
    progress: Any = None,
    step_loss: StepLoss | None = None,
) -> Constant | None:
    """The windows' terminal value of ``config.value_grid``: the task's grid dynamic program
    (``diffcontrol.optimal.solve``, 41 actions per action dimension) over the training
    horizon, solved with ``params``: ``V_0`` only (the best return of a whole episode from
    each state), or with ``config.value_time`` every ``V_t``; ``None`` without one.

    Raises:
        ConfigError: the task cannot have one (``check_value_grid``), or ``step_loss`` is not
            minus the reward (``check_reward_loss``).
    """
    if not config.value_grid:
        return None
    check_value_grid(task, config, params)
    if step_loss is not None:
        check_reward_loss(task, config, params, step_loss)
    horizon = config.horizon or task.episode_length
    if progress:
        progress(
            f"solving the windows' terminal value: the grid optimum of {config.value_grid} "
            "points per state axis"
        )
    if config.value_time:
        return Constant(optimal.solve(task, config.value_grid, params=params, horizon=horizon))
    return Constant(optimal.solve_first(task, config.value_grid, params=params, horizon=horizon))


def check_reward_loss(task: Task, config: TrainConfig, params: PyTree, step_loss: StepLoss) -> None:
    """Refuse a terminal value with a loss that is not minus the reward: the value is the
    best return to come, in reward units, so the windows' loss must be minus the reward for
    the two to add up. Checked on 64 reset states and random actions within the bounds.

    Raises:
        ConfigError: one line, naming the loss and the way out.
    """
    k_reset, k_act = jax.random.split(jax.random.PRNGKey(0))
    states = jax.vmap(lambda k: task.reset(k, params))(jax.random.split(k_reset, 64))
    low, high = (jnp.broadcast_to(jnp.asarray(b, jnp.float32), (task.action_size,))
                 for b in (task.action_low, task.action_high))  # fmt: skip
    actions = jax.random.uniform(k_act, (64, task.action_size), minval=low, maxval=high)

    def minus_reward(loss: StepLoss) -> bool:
        def gap(state: Array, action: Array) -> Array:
            next_state, reward, _ = task.step(params, state, action)
            return loss(params, state, action, next_state, reward) + reward

        return bool(
            np.allclose(np.asarray(jax.jit(jax.vmap(gap))(states, actions)), 0.0, atol=1e-4)
        )

    if not minus_reward(step_loss):
        fits = [n for n in getattr(task, "losses", ()) if minus_reward(task.step_loss(n))]
        fix = f"--loss {fits[0]}" if fits else "a loss that is minus the reward"
        what = f"loss {config.loss!r}" if config.loss else "the step_loss given"
        raise ConfigError(
            f"value_grid={config.value_grid} adds the best return to come (in reward units) to "
            f"each window, which needs a loss that is minus the reward; {what} is not: choose "
            f"{fix}, or --value-grid 0"
        )


def make_trainer(
    task: Task,
    config: TrainConfig,
    step_loss: StepLoss | None = None,
    params: PyTree = None,
    progress: Any = None,
    optimizer: optax.GradientTransformation | None = None,
) -> Trainer | PopulationTrainer:
    """Build the ``Trainer`` for ``task`` and ``config`` (validating the loss name); a
    ``PopulationTrainer`` of them when ``config.population > 1``. ``params`` (default the
    task's with ``config.params`` applied) are the physics a terminal value
    (``config.value_grid``) is solved with; ``optimizer`` replaces ``make_optimizer(config)``
    (a sweep's, whose learning rate is in its state)."""
    if step_loss is None:
        step_loss = task.step_loss(builtin_loss_name(task, config.loss, "step_loss"))
    if params is None and config.value_grid:
        params = task_params(task, config.params)
    trainer = Trainer(
        task=task,
        config=config,
        step_loss=step_loss,
        optimizer=optimizer or make_optimizer(config),
        horizon=config.horizon or task.episode_length,
        window=config.window,
        value=terminal_value(task, config, params, progress, step_loss),
    )
    if config.population > 1:
        return PopulationTrainer(trainer, config.population)
    return trainer


register_trainer(TrainConfig, TrainerKind(make_trainer, "discrete-time", "step_loss"))
