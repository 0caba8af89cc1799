"""Distillation: the plain MLP trained on the planner's own actions (DAgger), so that the fast
NumPy policy of ``model.json`` inherits the planner's quality.

DAgger (Ross, Gordon and Bagnell, "A reduction of imitation learning and structured prediction
to no-regret online learning", AISTATS 2011): round 0 rolls the planner out from the task's
start states and records, at every visited state, the observation and the planner's action;
every later round rolls out the current MLP (with probability ``beta ** round`` per step the
planner's action instead) and again labels every visited state with the planner's action, so
the data set grows where the MLP itself goes and its own mistakes get corrected. After every
round the MLP is fitted to all the data so far by minibatch regression.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float, PRNGKeyArray

from .. import _timing
from ..config import TrainConfig
from ..controllers import MLPController, head_inverse
from ..errors import ConfigError, SolverFailed
from ..rollout import batch_returns
from ..tasks import controller_kwargs
from ..training import TrainResult
from ..training._loop import Loop
from ._planner import Planner

_CONTINUOUS_HEADS = ("linear", "tanh", "sigmoid")


def _count(name: str, value: Any, least: int, fix: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
        raise ConfigError(f"{name}={value!r} must be an integer >= {least}; {fix}")
    return int(value)


def _fraction(name: str, value: Any, fix: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}={value!r} must be a number; {fix}") from None
    if not (0.0 <= x <= 1.0):
        raise ConfigError(f"{name}={value!r} must be in [0, 1]; {fix}")
    return x


def labelled_episodes(
    planner: Planner,
    controller: MLPController,
    starts: Float[Array, "B d"],
    keys: PRNGKeyArray,
    beta: Array,
    steps: int,
) -> tuple[Array, Array, Array, Array, Array]:
    """Closed-loop episodes in the planner's model from ``starts``, every visited state labelled
    with the planner's action (vmapped over the starts; jit it with ``steps`` static).

    At each step the planner solves from the state (warm-started from its own shifted plan of
    the step before, as when it drives), and the action applied is the planner's with
    probability ``beta`` (drawn per step from ``keys``), else the controller's. Steps after the
    model reports a termination are masked out.

    Returns:
        ``(observations [B, steps, obs], labels [B, steps, m], valid [B, steps],
        returns [B], finite [B, steps])``: the observation at each visited state, the
        planner's action there, whether the step is before any termination, each episode's
        return, and whether the planner's solve was finite (else its warm start was the label).
    """
    task, params = planner.task, planner.problem.params

    def episode(x0, key):
        def one(carry, k):
            x, warm, done = carry
            label, warm, info = planner.control(x, warm)
            obs = task.observe(x)
            own = controller(obs)
            u = jnp.where(jax.random.bernoulli(k, beta), label, own)
            nxt, reward, terminated = task.step(params, x, u)
            out = (obs, label, ~done, jnp.where(done, 0.0, reward), info.finite)
            return (nxt, warm, done | terminated), out

        init = (x0, planner.initial_plan(), jnp.asarray(False))
        _, (obs, labels, valid, rewards, finite) = jax.lax.scan(
            one, init, jax.random.split(key, steps)
        )
        return obs, labels, valid, rewards.sum(), finite

    return jax.vmap(episode)(starts, keys)


def _imitation_loss(controller, obs, targets):
    """Huber loss (delta 1) between the network's raw outputs and the targets' (``z`` before the
    action head). Fitted in ``z`` rather than in actions because a bounded head's derivative
    vanishes at its bounds: in action units the fit stops short of the saturated (bang-bang)
    actions a planner takes most of the time (1.9 N m for 2), which costs a swing-up its last
    bit of energy."""
    return jnp.mean(optax.huber_loss(jax.vmap(controller.logits)(obs), targets, delta=1.0))


@eqx.filter_jit
def _fit(controller, opt_state, optimizer, obs, targets, n, key, steps, batch_size):
    """``steps`` Adam steps on minibatches drawn (with replacement) from the first ``n`` rows of
    the fixed-size buffers ``obs``/``targets`` (one compiled program whatever ``n``)."""

    def one(carry, k):
        ctrl, state = carry
        idx = jax.random.randint(k, (batch_size,), 0, n)
        loss, grads = eqx.filter_value_and_grad(_imitation_loss)(ctrl, obs[idx], targets[idx])
        updates, state = optimizer.update(grads, state, eqx.filter(ctrl, eqx.is_inexact_array))
        return (eqx.apply_updates(ctrl, updates), state), loss

    (controller, opt_state), losses = jax.lax.scan(
        one, (controller, opt_state), jax.random.split(key, steps)
    )
    return controller, opt_state, losses


@eqx.filter_jit
def _rms_error(controller, obs, labels, span, start, stop):
    """Root-mean-square action error over rows ``start ... stop - 1`` of the fixed-size
    buffers, in units of the action range (one compiled program whatever the rows)."""
    rows = jnp.arange(obs.shape[0])
    inside = (rows >= start) & (rows < stop)
    squared = jnp.sum(((jax.vmap(controller)(obs) - labels) / span) ** 2, axis=-1)
    count = jnp.maximum(stop - start, 1) * labels.shape[-1]
    return jnp.sqrt(jnp.sum(jnp.where(inside, squared, 0.0)) / count)


def _default_controller(task: Any, config: TrainConfig, key: PRNGKeyArray) -> MLPController:
    """The task's default controller (the architecture ``train`` builds), randomly initialised."""
    kwargs = controller_kwargs(task)
    if config.head:
        kwargs["head"] = config.head
    return MLPController(key, hidden=config.hidden, activation=config.activation, **kwargs)


def _config_for(task: Any, seed: int) -> TrainConfig:
    config = task.default_config()
    if not isinstance(config, TrainConfig):
        config = TrainConfig()
    return config.replace(seed=seed)


def distil(
    task: Any,
    planner: Planner,
    controller: MLPController | None = None,
    *,
    rounds: int = 12,
    episodes_per_round: int = 128,
    beta: float = 0.0,
    fit_steps: int = 4000,
    batch_size: int = 512,
    learning_rate: float = 3e-3,
    eval_episodes: int = 256,
    keep_best: bool = True,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> TrainResult:
    """Distil ``planner`` into an MLP controller by DAgger (see the module docstring).

    Every round runs ``episodes_per_round`` episodes of ``task.episode_length`` steps from the
    task's reset distribution in the planner's model (``planner.problem.params``), all
    vmapped: round 0 driven by the planner, round ``i >= 1`` by the MLP with the planner's
    action mixed in with probability ``beta ** i`` per step. Every visited state (before any
    termination, and where the planner's solve was finite) is labelled with the planner's
    action and added to the data set; then the MLP
    takes ``fit_steps`` Adam steps (cosine-decayed over all rounds, from ``learning_rate`` to 5 %
    of it) on minibatches of ``batch_size`` drawn from all the data so far, minimising the
    squared action error in units of the action range. After every round the MLP is evaluated
    on ``eval_episodes`` simulated episodes (the same starts each round).

    Args:
        task: the planner's task (a discrete-time ``Task`` whose controller has a continuous
            head: ``tanh``, ``sigmoid`` or ``linear``).
        planner: the teacher, from ``mpc.make_planner``.
        controller: the MLP to start from; default the task's default controller (the
            architecture of ``task.default_config()``, as ``train`` builds it), randomly
            initialised from ``seed``, so that the result saves, loads and exports like any
            trained controller.
        rounds: DAgger rounds, >= 1 (round 0 is the planner's own rollouts).
        episodes_per_round: episodes rolled out (and labelled) per round, >= 1.
        beta: in ``[0, 1]``; the chance per step that round ``i >= 1`` applies the planner's
            action is ``beta ** i`` (0: the MLP alone, the usual choice).
        fit_steps: Adam steps after each round, >= 1.
        batch_size: rows per minibatch, >= 1.
        learning_rate: Adam's peak learning rate, finite and > 0.
        eval_episodes: simulated episodes of each round's evaluation, >= 1.
        keep_best: return the MLP of the round with the best evaluation return (else the last).
        seed: PRNG seed: the run is a function of it.
        progress: called with one line per round.

    Returns:
        A ``diffcontrol.TrainResult`` (``result.save(dir)``, then ``diffcontrol.load(dir)``
        and ``diffcontrol.evaluate``), whose ``metrics["curve"]`` has one point per round
        (the MLP's evaluation return, its action error on the round's new states before the
        fit and on all the data after it, how many states were labelled) and
        ``metrics["distillation"]`` the settings, the planner's own simulated return and the
        number of planner calls.

    Raises:
        ConfigError: a count out of range, ``beta`` outside ``[0, 1]``, a non-positive learning
            rate, a task whose controller has a discrete head, or a planner of another task.
        SolverFailed: every solve of round 0 was non-finite (no data to fit).
    """
    fix = "pass a positive integer"
    rounds = _count("rounds", rounds, 1, "round 0 is the planner's own rollouts; use >= 1")
    episodes = _count("episodes_per_round", episodes_per_round, 1, fix)
    fit_steps = _count("fit_steps", fit_steps, 1, fix)
    batch_size = _count("batch_size", batch_size, 1, fix)
    eval_episodes = _count("eval_episodes", eval_episodes, 1, fix)
    seed = _count("seed", seed, 0, "use a seed >= 0")
    beta = _fraction("beta", beta, "it is the chance of the planner's action in round 1")
    lr = float(learning_rate) if isinstance(learning_rate, int | float) else math.nan
    if not (math.isfinite(lr) and lr > 0):
        raise ConfigError(f"learning_rate={learning_rate!r} must be a finite number > 0")
    if not isinstance(planner, Planner):
        raise ConfigError(f"planner={planner!r} is not a Planner; build one with mpc.make_planner")
    if planner.task is not task and planner.task.name != task.name:
        raise ConfigError(
            f"the planner plans for task {planner.task.name!r}, not {task.name!r}; "
            "build it with mpc.make_planner(task, ...)"
        )
    config = _config_for(task, seed)
    head = controller.head if controller is not None else (config.head or task.action_head)
    if head not in _CONTINUOUS_HEADS:
        raise ConfigError(
            f"task {task.name!r}'s controller has the {head!r} head; distillation regresses "
            f"continuous actions, so it needs one of {', '.join(_CONTINUOUS_HEADS)}"
        )

    _timing.watch_compiles()
    t_start, compiled_before = time.perf_counter(), _timing.compile_seconds()
    programs_before = _timing.compiled_programs()
    say = progress or (lambda line: None)
    steps = task.episode_length
    params = planner.problem.params
    k_ctrl, k_eval, k_run = jax.random.split(jax.random.PRNGKey(seed), 3)
    if controller is None:
        controller = _default_controller(task, config, k_ctrl)
    span = planner.problem.high - planner.problem.low
    schedule = optax.cosine_decay_schedule(lr, rounds * fit_steps, alpha=0.05)
    optimizer = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(schedule))
    opt_state = optimizer.init(eqx.filter(controller, eqx.is_inexact_array))
    evaluate = jax.jit(batch_returns, static_argnums=(0, 4))
    eval_keys = jax.random.split(k_eval, eval_episodes)

    say(
        f"distilling the planner into the MLP: {rounds} rounds of {episodes} episodes "
        f"({episodes * steps} planner calls each), {fit_steps} fit steps per round; "
        "compiling first"
    )
    distiller = _Distiller(
        task, planner, optimizer, rounds, episodes, beta, fit_steps, batch_size, span
    )
    budget = SimpleNamespace(updates=rounds * fit_steps, target_return=math.nan)
    loop = _DistilLoop(
        distiller,
        [budget],
        params,
        lambda ctrl, params, keys: evaluate(task, params, ctrl, keys, steps),
        eval_keys,
        [(budget.updates, distiller.chunk)],
        say,
        best=controller,
        t_start=t_start,
    )
    ts = loop.run(_Round(update=0, controller=controller, opt_state=opt_state, key=k_run))
    curve, n = loop.curves[0], distiller.n
    chosen = curve[loop.best_index[0]] if keep_best else curve[-1]
    controller = loop.best if keep_best else ts.controller
    wall = time.perf_counter() - t_start
    compile_s = _timing.compile_seconds() - compiled_before
    metrics = {
        "task": task.name,
        "gym_id": task.gym_id,
        "seed": seed,
        "train_seconds": wall,
        "compile_seconds": compile_s,
        "timings": {
            "compile": compile_s,
            "compile_programs": _timing.compiled_programs() - programs_before,
            "train": wall - compile_s,
        },
        "updates": rounds * fit_steps,
        "simulated_steps": rounds * episodes * steps,
        "simulated_episodes": float(rounds * episodes),
        "episode_length": steps,
        "stopped_early": False,
        "returned_update": chosen["update"],
        "final_eval_return": chosen["eval_return"],
        "final_eval_return_std": chosen["eval_return_std"],
        "eval_episodes": eval_episodes,
        "num_parameters": controller.num_parameters,
        "curve": curve,
        "warnings": [],
        "config": config.to_json(),
        "distillation": {
            "method": "DAgger",
            "rounds": rounds,
            "episodes_per_round": episodes,
            "beta": beta,
            "fit_steps": fit_steps,
            "batch_size": batch_size,
            "learning_rate": lr,
            "keep_best": keep_best,
            "returned_round": chosen["round"],
            "planner": _describe(planner),
            "planner_return": distiller.planner_return,
            "planner_calls": rounds * episodes * steps,
            "labelled_states": n,
            "non_finite_solves": distiller.non_finite,
        },
        "jax_version": jax.__version__,
        "device": str(jax.devices()[0].platform),
        "devices": 1,
        "processes": 1,
    }
    return TrainResult(
        task=task, config=config, params=params, controller=controller, metrics=metrics
    )


@dataclasses.dataclass
class _Round:
    """A distillation's state between rounds (the loop's training state)."""

    update: int  # fit steps so far
    controller: MLPController
    opt_state: Any
    key: PRNGKeyArray
    point: dict[str, Any] = dataclasses.field(default_factory=dict)  # the last round's figures


class _Distiller:
    """DAgger as a trainer on the training loop (``training._loop``): one chunk is one round
    (roll out, label every visited state with the planner's action, fit the MLP to all the
    data so far), its evaluation point the MLP's return; the data set is kept here, in
    fixed-size buffers (one compiled fit whatever its size)."""

    def __init__(
        self, task, planner, optimizer, rounds, episodes, beta, fit_steps, batch_size, span
    ) -> None:
        self.task, self.planner, self.optimizer, self.span = task, planner, optimizer, span
        self.episodes, self.beta = episodes, beta
        self.fit_steps, self.batch_size = fit_steps, batch_size
        self.steps = task.episode_length
        capacity = rounds * episodes * self.steps
        self.obs = np.zeros((capacity, task.observation_size), np.float32)
        self.labels = np.zeros((capacity, planner.action_size), np.float32)
        self.targets = np.zeros_like(self.labels)  # the labels as the network's raw outputs
        self.n, self.non_finite, self.planner_return = 0, 0, math.nan
        self.rollout = jax.jit(labelled_episodes, static_argnums=5)

    def chunk(self, ts: _Round, params: Any, total: Any) -> tuple[_Round, SimpleNamespace]:
        """One round of DAgger."""
        task, planner, episodes, steps = self.task, self.planner, self.episodes, self.steps
        r = ts.update // self.fit_steps
        k_run, k_starts, k_mix, k_fit = jax.random.split(ts.key, 4)
        starts = jax.vmap(task.reset, in_axes=(0, None))(
            jax.random.split(k_starts, episodes), params
        )
        mix = jnp.asarray(1.0 if r == 0 else self.beta**r, jnp.float32)
        controller = ts.controller
        obs, labels, valid, returns, finite = self.rollout(
            planner, controller, starts, jax.random.split(k_mix, episodes), mix, steps
        )
        # Kept: the states before any termination whose solve was finite (where it was not,
        # the label would be the planner's fallback, not its plan).
        valid, finite = np.asarray(valid).reshape(-1), np.asarray(finite).reshape(-1)
        self.non_finite += int(np.sum(valid & ~finite))
        keep = valid & finite
        new_obs = np.asarray(obs).reshape(-1, task.observation_size)[keep]
        new_labels = np.asarray(labels).reshape(-1, planner.action_size)[keep]
        if r == 0:
            self.planner_return = float(np.mean(returns))
        n, rows = self.n, slice(self.n, self.n + len(new_obs))
        self.obs[rows], self.labels[rows] = new_obs, new_labels
        low, high = controller.action_low, controller.action_high
        self.targets[rows] = np.asarray(head_inverse(controller.head, new_labels, low, high))
        obs_all, label_all = jnp.asarray(self.obs), jnp.asarray(self.labels)
        # The MLP's error on the states it (or the planner, in round 0) just visited, before
        # it is fitted to them: DAgger's measure of how far its own distribution is from the
        # data's.
        on_policy = float(
            _rms_error(
                controller, obs_all, label_all, self.span, jnp.int32(n), jnp.int32(rows.stop)
            )
        )
        self.n = n = rows.stop
        if n == 0:
            raise SolverFailed(
                "every planner solve of round 0 was non-finite, so there is nothing to fit; "
                "check the planner on one state (planner.plan) and its cost for NaN"
            )
        controller, opt_state, losses = _fit(
            controller, ts.opt_state, self.optimizer, obs_all, jnp.asarray(self.targets),
            jnp.int32(n), k_fit, self.fit_steps, self.batch_size,
        )  # fmt: skip
        fitted = float(
            _rms_error(controller, obs_all, label_all, self.span, jnp.int32(0), jnp.int32(n))
        )
        losses = np.asarray(losses)
        point = {
            "round": r,
            "simulated_steps": (r + 1) * episodes * steps,
            "simulated_episodes": float((r + 1) * episodes),
            "planner_calls": (r + 1) * episodes * steps,
            "labelled_states": n,
            "planner_share": float(mix),
            "rollout_return": float(np.mean(returns)),
            "on_policy_error": on_policy,
            "fitted_error": fitted,
            "loss": float(np.mean(losses[-max(1, self.fit_steps // 10) :])),
        }
        new = _Round(ts.update + self.fit_steps, controller, opt_state, k_run, point)
        return new, SimpleNamespace(loss=losses, grad_norm=np.full_like(losses, np.nan))

    # --- the loop's hooks ----------------------------------------------------------------

    def summarize(self, returns: np.ndarray) -> tuple[float, float]:
        return float(np.mean(returns)), float(np.std(returns))

    def pick(self, controller: MLPController, returns: np.ndarray) -> MLPController:
        return controller

    def check(self, old: _Round, new: _Round, losses: np.ndarray) -> list[str]:
        return []


class _DistilLoop(Loop):
    """The training loop over DAgger's rounds: no point before the first round (the untrained
    MLP is not a candidate), each round's point and progress line its own."""

    def point(self, ts, i, update, returns, loss, grad_norm, seconds) -> dict[str, Any]:
        mean, std = self.trainer.summarize(returns)
        return {
            "update": update,
            **ts.point,
            "eval_return": mean,
            "eval_return_std": std,
            "seconds": seconds,
        }

    def points_made(self, ts: _Round, returns: np.ndarray, points: list[dict | None]) -> None:
        p = points[0]
        r = p["round"]
        who = "planner" if r == 0 else f"MLP (planner share {p['planner_share']:.2f})"
        self.say(
            f"round {r + 1}/{self.budgets[0] // self.trainer.fit_steps}  rollouts by {who}: "
            f"return {p['rollout_return']:8.2f}  labelled {p['labelled_states']:7d}  error "
            f"before fit {p['on_policy_error']:.4f}  after {p['fitted_error']:.4f}"
            f"  MLP eval return {p['eval_return']:8.2f}  {p['seconds']:6.1f} s"
        )


def _describe(planner: Planner) -> dict[str, Any]:
    """The planner's settings as JSON (for ``metrics.json``)."""
    solver = planner.solver
    fields = {k: v for k, v in vars(solver).items() if isinstance(v, int | float | bool | str)}
    return {
        "solver": type(solver).__name__,
        **fields,
        "horizon": planner.horizon,
        "bound_starts": planner.bound_starts,
        "terminal_cost": planner.problem.terminal_cost is not None,
        "terminal_weight": float(planner.problem.terminal_weight),
    }
