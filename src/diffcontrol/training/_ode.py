"""Training through an ODE solve: the pure, jitted part of the continuous-time trainer.

One *update* solves the closed loop of every population member from the task's initial state
over the (possibly growing) horizon, differentiates each member's loss on its saved
trajectory through its solve, and takes one optimiser step per member, all under ``vmap``.
With ``window_s`` the horizon is cut into consecutive windows instead, each solved from where
the last one ended, its loss differentiated through its own solve only, one step per window:
over a long swing-up, the gradient through the whole solve is dominated by how the end state
depends on the first seconds' actions (norms of 1e2 to 1e3) and no longer points downhill.
A member whose solve fails (its step limit, a step too small) or whose loss or gradient is
not finite is frozen and flagged, never updated with a NaN; the Python driver reports it and
stops with a clear error when no member is left. A *chunk* is ``lax.scan`` over
``eval_every`` updates under one ``jit``, as for the discrete-time trainer.
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float, Int, PRNGKeyArray, PyTree

from ..config import MAX_COUNT, ODETrainConfig
from ..controllers import MLPController
from ..errors import ConfigError, SolverFailed
from ..rollout import force_fn, solve_closed_loop, value_and_grad
from ..tasks import ContinuousTask, TrajectoryLoss, controller_kwargs
from ._bptt import builtin_loss_name, make_optimizer
from ._interface import TrainerKind, register_trainer

FAIL_NONE, FAIL_MAX_STEPS, FAIL_SOLVER, FAIL_NAN = 0, 1, 2, 3


def unbatched_member(task: Any) -> bool:
    """Whether the task's own class lets a population of 1 go unbatched: it declares
    ``one_member_unbatched = True``.

    A population of 1 is then differentiated and evaluated as one member, not under ``vmap``:
    batching Diffrax's loops is much of tracing and compiling the training chunk, so it is
    faster, but XLA then fuses the arithmetic differently and may round it differently. A
    built-in task declares it where its default settings and every recipe with a population
    of 1 trained to the same weights, bit for bit (docs/benchmarks.md). Read from the task's
    own class only: a subclass (another system, a fitted model) keeps the batched programs
    unless it declares its own."""
    return bool(vars(type(task)).get("one_member_unbatched", False))


class ODETrainState(eqx.Module):
    """What a continuous-time run carries between updates (and checkpoints).

    ``controller`` and ``opt_state`` have a leading population axis on every array.
    ``fail_code[i]`` is 0 while member ``i`` trains, else why it was frozen (``FAIL_*``), and
    ``fail_update[i]`` the update at which that happened.
    """

    controller: MLPController
    opt_state: PyTree
    fail_code: Int[Array, " population"]
    fail_update: Int[Array, " population"]
    update: Int[Array, ""]
    solves: Int[Array, ""]
    solver_steps: Int[Array, ""]
    simulated_seconds: Float[Array, ""]
    key: PRNGKeyArray  # draws the starts of each update (``starts > 1``)


class ODEUpdateStats(eqx.Module):
    """Per-update diagnostics (means over the members still training), stacked over a chunk."""

    loss: Float[Array, ""]
    grad_norm: Float[Array, ""]


def _trainable(controller: MLPController) -> Any:
    """A filter spec: the weights and biases of the layers (not the fixed scalings)."""
    spec = jax.tree.map(lambda _: False, controller)
    return eqx.tree_at(
        lambda c: c.layers, spec, replace=jax.tree.map(eqx.is_inexact_array, controller.layers)
    )


class ODETrainer(eqx.Module):
    """The pure functions of one continuous-time training configuration."""

    task: ContinuousTask = eqx.field(static=True)
    config: ODETrainConfig = eqx.field(static=True)
    loss_fn: TrajectoryLoss = eqx.field(static=True)
    optimizer: optax.GradientTransformation = eqx.field(static=True)

    episode_length = 1  # one closed-loop solve counts as one simulated episode

    # --- pure parts -----------------------------------------------------------------------

    def new_controller(self, key: PRNGKeyArray) -> MLPController:
        cfg = self.config
        kwargs = controller_kwargs(self.task)
        if cfg.head:
            kwargs["head"] = cfg.head
        return MLPController(key, hidden=cfg.hidden, activation=cfg.activation, **kwargs)

    def horizon_at(self, update: Array) -> Array:
        """The curriculum's horizon (s) at ``update``: growing linearly, then the full one."""
        cfg = self.config
        if cfg.curriculum_start >= 1:
            return jnp.asarray(cfg.horizon_s, float)
        growth = max(1.0, cfg.curriculum_fraction * cfg.updates)
        frac = cfg.curriculum_start + (1 - cfg.curriculum_start) * update / growth
        return cfg.horizon_s * jnp.minimum(1.0, frac)

    def solve(
        self,
        controller: MLPController,
        params: PyTree,
        horizon: Array,
        gradient: str,
        y0=None,
        saves: int | None = None,
        t0: Array | None = None,
    ):
        """One member's closed-loop solve from ``y0`` (default: the task's initial state) at
        time ``t0`` (default 0), saved at ``saves`` (default: the config's) points of
        ``[t0, t0 + horizon]``."""
        cfg = self.config
        ts = jnp.linspace(0.0, 1.0, saves or cfg.saves) * horizon
        if t0 is not None:
            ts = t0 + ts
        args = (params, force_fn(self.task, controller))
        return solve_closed_loop(
            self.task.vector_field,
            self.task.initial_state(params) if y0 is None else y0,
            ts,
            args,
            solver=cfg.solver,
            rtol=cfg.rtol,
            atol=cfg.atol,
            max_steps=cfg.max_steps,
            gradient=gradient,
        )

    def member_loss(self, controller: MLPController, params: PyTree, horizon: Array, y0s=None):
        """``(loss, (solution flags))`` of one member: the loss of its saved trajectory, or
        the mean loss of the trajectories from the initial states ``y0s`` (``[starts, state]``:
        every solve must succeed)."""
        if y0s is None:
            loss, (ok, hit_max, steps, _) = self._loss_and_ends(controller, params, horizon, None)
            return loss, (ok, hit_max, steps)
        loss, (ok, hit_max, steps, _) = jax.vmap(
            lambda y0: self._loss_and_ends(controller, params, horizon, y0)
        )(y0s)
        return jnp.mean(loss), (jnp.all(ok), jnp.any(hit_max), jnp.sum(steps))

    def _loss_and_ends(self, controller, params, horizon, y0, saves=None, t0=None):
        """The loss of one solve from ``y0`` at ``t0`` over ``horizon`` (``saves`` points),
        its flags and its end state."""
        sol = self.solve(controller, params, horizon, self.config.gradient, y0, saves, t0)
        traj = self.task.trajectory(params, controller, sol.ts, sol.ys)
        loss = jnp.reshape(self.loss_fn(traj), ())
        return loss, (sol.ok, sol.max_steps_reached, sol.num_steps, sol.ys[-1])

    def starts_of(self, key: PRNGKeyArray, params: PyTree):
        """``starts`` initial states from the task's reset distribution, or ``None`` (the one
        initial state) when ``starts`` is 1."""
        if self.config.starts == 1:
            return None
        return jax.vmap(lambda k: self.task.reset(k, params))(
            jax.random.split(key, self.config.starts)
        )

    def init(self, key: PRNGKeyArray, params: PyTree) -> ODETrainState:
        """``population`` random controllers (one key each) and their optimiser states."""
        n = self.config.population
        controllers = eqx.filter_vmap(self.new_controller)(jax.random.split(key, n))
        diff = eqx.filter(controllers, _trainable(self.new_controller(key)))
        opt_state = eqx.filter_vmap(self.optimizer.init)(diff)
        zero = jnp.zeros((), jnp.int32)
        return ODETrainState(
            controller=controllers,
            opt_state=opt_state,
            fail_code=jnp.zeros((n,), jnp.int32),
            fail_update=jnp.full((n,), -1, jnp.int32),
            update=zero,
            solves=zero,
            solver_steps=zero,
            simulated_seconds=jnp.zeros((), float),
            key=jax.random.fold_in(key, 1),
        )

    def _one_member(self) -> bool:
        """A population of 1 that the task lets go unbatched (``unbatched_member``)."""
        return self.config.population == 1 and unbatched_member(self.task)

    def _member_grad(self, controller, params, horizon, y0s):
        """One member's loss, its solve's flags and the gradient of its trainable weights."""
        diff, static = eqx.partition(controller, _trainable(controller))

        def loss_of(diff):
            return self.member_loss(eqx.combine(diff, static), params, horizon, y0s)

        grad_fn = value_and_grad(loss_of, self.config.gradient)
        (loss, (ok, hit_max, num_steps)), grads = grad_fn(diff)
        return loss, ok, hit_max, num_steps, grads

    def _member_apply(self, controller, opt_state, fail_code, loss, ok, hit_max, num_steps, grads):
        diff, static = eqx.partition(controller, _trainable(controller))
        grad_norm = optax.tree_utils.tree_norm(grads)
        finite = jnp.isfinite(loss) & jnp.isfinite(grad_norm)
        code = jnp.where(ok, jnp.where(finite, FAIL_NONE, FAIL_NAN), FAIL_SOLVER)
        code = jnp.where(hit_max, FAIL_MAX_STEPS, code)
        live = fail_code == FAIL_NONE
        good = live & (code == FAIL_NONE)
        # Never let a failed solve's inf/nan reach the weights: zero the gradient, keep the old
        # weights and optimiser state, and freeze the member.
        grads = jax.tree.map(lambda g: jnp.where(good, g, 0.0), grads)
        updates, new_opt = self.optimizer.update(grads, opt_state, diff)
        new_diff = eqx.apply_updates(diff, updates)
        new_diff = jax.tree.map(lambda n, o: jnp.where(good, n, o), new_diff, diff)
        new_opt = jax.tree.map(lambda n, o: jnp.where(good, n, o), new_opt, opt_state)
        new_code = jnp.where(live, code, fail_code)
        return (
            eqx.combine(new_diff, static),
            new_opt,
            new_code,
            jnp.where(good, loss, jnp.nan),
            jnp.where(good, grad_norm, jnp.nan),
            jnp.where(live, num_steps, 0),
            live,
        )

    def windows(self) -> int:
        """Consecutive windows per update (``window_s``): 1 differentiates the whole horizon."""
        return windows_of(self.config)

    def _window_steps(self, ts: ODETrainState, params: PyTree, horizon: Array, y0s):
        """Truncated BPTT through the solve: ``windows()`` consecutive windows of the horizon,
        each differentiated through its own solve only and giving one optimiser step per
        member; a window's end states start the next one without gradient, at the time they
        were reached."""
        cfg = self.config
        k = self.windows()
        saves = window_saves(cfg)
        window = horizon / k
        if y0s is None:
            y0s = self.task.initial_state(params)[None]
        ys = jnp.broadcast_to(y0s, (cfg.population, *y0s.shape))

        def grad_one(controller, ys, t0):
            diff, static = eqx.partition(controller, _trainable(controller))

            def loss_of(diff):
                ctrl = eqx.combine(diff, static)
                loss, (ok, hit, steps, ends) = jax.vmap(
                    lambda y0: self._loss_and_ends(ctrl, params, window, y0, saves, t0)
                )(ys)
                return jnp.mean(loss), (jnp.all(ok), jnp.any(hit), jnp.sum(steps), ends)

            (loss, (ok, hit, steps, ends)), grads = value_and_grad(loss_of, cfg.gradient)(diff)
            return loss, ok, hit, steps, grads, jax.lax.stop_gradient(ends)

        def body(carry, j):
            ctrl, opt, code, ys = carry
            grad_members = eqx.filter_vmap(grad_one, in_axes=(0, 0, None))
            loss, ok, hit, steps, grads, ends = grad_members(ctrl, ys, j * window)
            ctrl, opt, code, loss, gnorm, steps, live = eqx.filter_vmap(self._member_apply)(
                ctrl, opt, code, loss, ok, hit, steps, grads
            )
            ends = jnp.where(jnp.isfinite(ends), ends, ys)  # a failed member is frozen anyway
            return (ctrl, opt, code, ends), (loss, gnorm, steps, live)

        carry = (ts.controller, ts.opt_state, ts.fail_code, ys)
        (ctrl, opt, code, _), (loss, gnorm, steps, live) = jax.lax.scan(body, carry, jnp.arange(k))
        # the members live when the update began: those whose solves it counts
        return ctrl, opt, code, jnp.nanmean(loss, 0), jnp.nanmean(gnorm, 0), steps.sum(0), live[0]

    def update(self, ts: ODETrainState, params: PyTree) -> tuple[ODETrainState, ODEUpdateStats]:
        """One update of every member still training."""
        horizon = self.horizon_at(ts.update)
        key, k_starts = jax.random.split(ts.key)
        y0s = self.starts_of(k_starts, params)  # the same starts for every member
        # One member's solve differentiated as it is, not under vmap, where the task says so
        # (``_one_member``); the optimiser's step stays under vmap.
        if self.windows() > 1:
            ctrl, opt, code, loss, gnorm, steps, live = self._window_steps(ts, params, horizon, y0s)
        else:
            if self._one_member():
                out = _as_members(self._member_grad(_only(ts.controller), params, horizon, y0s))
            else:
                out = eqx.filter_vmap(self._member_grad, in_axes=(0, None, None, None))(
                    ts.controller, params, horizon, y0s
                )
            ctrl, opt, code, loss, gnorm, steps, live = eqx.filter_vmap(self._member_apply)(
                ts.controller, ts.opt_state, ts.fail_code, *out
            )
        newly = (code != FAIL_NONE) & (ts.fail_code == FAIL_NONE)
        n_live = jnp.sum(live)
        new = ODETrainState(
            controller=ctrl,
            opt_state=opt,
            fail_code=code,
            fail_update=jnp.where(newly, ts.update + 1, ts.fail_update),
            update=ts.update + 1,
            solves=ts.solves + (n_live * self.config.starts).astype(jnp.int32),
            solver_steps=ts.solver_steps + jnp.sum(steps).astype(jnp.int32),
            simulated_seconds=ts.simulated_seconds + n_live * self.config.starts * horizon,
            key=key,
        )
        stats = ODEUpdateStats(loss=jnp.nanmean(loss), grad_norm=jnp.nanmean(gnorm))
        return new, stats

    def chunk(self, ts: ODETrainState, params: PyTree, total_updates: Array):
        """``eval_every`` updates under one ``lax.scan``; updates past ``total_updates`` skipped."""

        def body(ts, _):
            def skip(ts, params):
                nan = jnp.full((), jnp.nan, float)
                return ts, ODEUpdateStats(loss=nan, grad_norm=nan)

            return jax.lax.cond(ts.update < total_updates, self.update, skip, ts, params)

        return jax.lax.scan(body, ts, None, length=self.config.eval_every)

    def evaluate(self, controller: MLPController, params: PyTree, key: PRNGKeyArray) -> Array:
        """Each member's return, minus its loss over the full horizon (``-inf`` if it failed):
        from the initial state, or its mean over ``starts`` fixed starts drawn with ``key``."""
        y0s = self.starts_of(key, params)

        def one(ctrl):
            horizon = jnp.asarray(self.config.horizon_s)
            loss, (ok, _, _) = self.member_loss(ctrl, params, horizon, y0s)
            return jnp.where(ok & jnp.isfinite(loss), -loss, -jnp.inf)

        if self._one_member():  # as in ``update``
            return _as_members(one(_only(controller)))
        return eqx.filter_vmap(one)(controller)

    # --- the driver's hooks (plain Python, between chunks) --------------------------------

    def stages(self) -> list[tuple[int, ODETrainer]]:
        """One stage: the horizon curriculum runs inside the programs (``horizon_at``)."""
        return [(self.config.updates, self)]

    def summarize(self, returns: np.ndarray) -> tuple[float, float]:
        """The best member's return, and the spread over the members that are finite."""
        ok = np.isfinite(returns)
        if not ok.any():
            return -math.inf, math.nan
        return float(np.max(returns[ok])), float(np.std(returns[ok]))

    def pick(self, controller: MLPController, returns: np.ndarray) -> MLPController:
        """The member with the best return (the first if none is finite)."""
        i = int(np.argmax(np.where(np.isfinite(returns), returns, -np.inf)))
        # Sliced by NumPy and placed back: no program compiled per weight array.
        return jax.tree.map(
            lambda x: jax.device_put(np.asarray(x)[i]) if eqx.is_array(x) else x, controller
        )

    def counts(self, ts: ODETrainState) -> dict[str, Any]:
        return {
            "simulated_episodes": int(ts.solves),
            "simulated_steps": int(ts.solver_steps),
            "simulated_seconds": float(ts.simulated_seconds),
            "horizon_s": float(self.horizon_at(ts.update)),
        }

    def point_extras(self, ts: ODETrainState, returns: np.ndarray) -> dict[str, Any]:
        return {
            "eval_loss": -self.summarize(returns)[0],
            "members_training": int(np.sum(np.asarray(ts.fail_code) == FAIL_NONE)),
        }

    def check(self, old: ODETrainState, new: ODETrainState, losses: np.ndarray) -> list[str]:
        """Notes on members frozen in this chunk; raises ``SolverFailed`` if none is left."""
        old_code, code = np.asarray(old.fail_code), np.asarray(new.fail_code)
        notes = []
        for i in np.flatnonzero((old_code == FAIL_NONE) & (code != FAIL_NONE)):
            why = failure_message(int(code[i]), self.config)
            at = int(np.asarray(new.fail_update)[i])
            who = f"member {i} of {len(code)}" if len(code) > 1 else "the controller"
            notes.append(f"update {at}: {who} stopped training: {why}")
        if np.all(code != FAIL_NONE):
            raise SolverFailed(
                "training stopped: " + "; ".join(notes or ["every member had failed before"])
            )
        return notes

    def num_parameters(self, controller: MLPController) -> int:
        return sum(int(np.prod(l.weight.shape[-2:])) + l.bias.shape[-1] for l in controller.layers)

    def check_start(self, ts: ODETrainState, params: PyTree) -> None:
        """No member's loss is finite before any update: the loss or the solve is at fault."""
        ctrl = self.pick(ts.controller, np.zeros(self.config.population))
        loss, (ok, hit_max, _) = jax.jit(self.member_loss)(
            ctrl, params, jnp.asarray(self.config.horizon_s)
        )
        code = FAIL_MAX_STEPS if bool(hit_max) else FAIL_SOLVER if not bool(ok) else FAIL_NAN
        what = failure_message(code, self.config)
        if code == FAIL_NAN:
            raise ConfigError(
                f"the loss is {float(loss)} for the untrained controller although the ODE solve "
                "succeeded; the loss function must return a finite number"
            )
        raise ConfigError(f"the untrained controller's closed loop cannot be solved: {what}")


def _only(members: PyTree) -> PyTree:
    """The one member of a population of 1 (its arrays without the members' axis)."""
    return jax.tree.map(lambda x: x[0] if eqx.is_array(x) else x, members)


def _as_members(member: PyTree) -> PyTree:
    """One member's outputs given the members' axis back."""
    return jax.tree.map(lambda x: x[None] if eqx.is_array(x) else x, member)


def failure_message(code: int, config: ODETrainConfig) -> str:
    """What went wrong (a ``FAIL_*`` code) and what to change."""
    if code == FAIL_MAX_STEPS:
        return (
            f"the ODE solve reached its step limit (max_steps={config.max_steps}); raise "
            "--max-steps, loosen --rtol/--atol, or lower --learning-rate"
        )
    if code == FAIL_SOLVER:
        return (
            "the ODE solver failed (its step size became too small: a stiff or exploding "
            "closed loop); try --solver kvaerno5, tighter --rtol/--atol, or a lower "
            "--learning-rate"
        )
    return (
        "the loss or its gradient became non-finite although the solve succeeded; check the "
        "loss function, or lower --learning-rate / set --grad-clip"
    )


def make_ode_trainer(
    task: ContinuousTask, config: ODETrainConfig, trajectory_loss: TrajectoryLoss | None = None
) -> ODETrainer:
    """Build the ``ODETrainer`` for ``task``, checking the loss on an abstract trajectory.

    Raises:
        ConfigError: an unknown loss name, or a loss that does not return a scalar.
    """
    if trajectory_loss is None:
        name = builtin_loss_name(task, config.loss, "trajectory_loss")
        trajectory_loss = task.trajectory_loss(name)
    # A schedule spans every optimiser step: one per window of each update.
    steps = config.replace(updates=min(MAX_COUNT, config.updates * windows_of(config)))
    trainer = ODETrainer(
        task=task, config=config, loss_fn=trajectory_loss, optimizer=make_optimizer(steps)
    )
    _check_loss(trainer)
    return trainer


def windows_of(config: ODETrainConfig) -> int:
    """Consecutive windows per update (``window_s``): 1 differentiates the whole horizon."""
    if config.window_s <= 0:
        return 1
    return max(1, round(config.horizon_s / config.window_s))


def window_saves(config: ODETrainConfig) -> int:
    """The saved points of each window: its share of ``saves``, both ends included."""
    return max(2, round((config.saves - 1) / windows_of(config)) + 1)


def _check_loss(trainer: ODETrainer) -> None:
    """Trace the loss on an abstract trajectory of the horizon's saved points, and of a
    window's where the horizon is cut into windows: it must return one number."""
    task, cfg = trainer.task, trainer.config
    for saves in sorted({cfg.saves, window_saves(cfg)}, reverse=True):

        def traj_loss(params, saves=saves):
            ctrl = trainer.new_controller(jax.random.PRNGKey(0))
            ts = jnp.linspace(0.0, cfg.horizon_s, saves)
            ys = jnp.zeros((saves, task.initial_state(params).shape[0]))
            return trainer.loss_fn(task.trajectory(params, ctrl, ts, ys))

        where = "" if saves == cfg.saves else f" of a window's {saves} saved points (window_s)"
        try:
            out = jax.eval_shape(traj_loss, task.default_params())
        except Exception as e:  # a user's loss can fail in any way; say whose fault it is
            raise ConfigError(
                f"the loss function failed on a {type(e).__name__}{where}: {e}; it must take "
                "the task's trajectory object and return a scalar"
            ) from None
        shape = getattr(out, "shape", None)
        if shape is None or int(np.prod(shape)) != 1:
            raise ConfigError(
                f"the loss must return a scalar, but it returned shape {shape}{where}; reduce "
                "it (e.g. with jnp.sum or jnp.mean)"
            )


def _ode_factory(task, config, trajectory_loss, params=None, progress=None) -> ODETrainer:
    return make_ode_trainer(task, config, trajectory_loss)


register_trainer(
    ODETrainConfig,
    TrainerKind(
        _ode_factory,
        "continuous-time",
        "trajectory_loss",
        one_device="its solves run on one device (devices > 1 splits the batch of "
        "discrete-time tasks)",
    ),
)
