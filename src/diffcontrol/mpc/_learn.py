"""Learning a planner's terminal value (and warm-start policy) end to end, through the planner.

``learn_value`` has two stages. The initialisation is fitted value iteration on the planner's
own rollouts (approximate policy iteration): roll the planner out from the task's start states
with the current value network as its terminal cost, label every visited state with its
cost-to-go along the rollout (the running costs to the episode's end plus the network's value of
the last state), regress the network on these labels, and repeat with the new network. The
end-to-end stage then takes Adam steps on the closed-loop loss itself, minus the mean return of
``planner.episode`` from a batch of start states, differentiated in the network's weights
through every step's plan (``gradient="implicit"``: the implicit function theorem at each
optimum; or ``"unroll"``: through the solver's iterations, which also reaches a warm-start
policy). Every round and every few steps the planner is evaluated on the same simulated
episodes, and the best network is kept. A planner of the seed's idea: the model is given, and
what is learned is only what the model cannot give in H steps, the value beyond the horizon.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float

from ..errors import ConfigError
from ._planner import GRADIENTS, Planner
from ._value import ValueNetwork

TARGETS = ("rollout", "plan", "best")
"""What a visited state is labelled with in the initialisation (``learn_value(target=...)``)."""


def _install(planner: Planner, trainable: tuple[Any, Any]) -> Planner:
    """``planner`` with the terminal cost and the warm-start policy of ``trainable``."""
    value, policy = trainable
    planner = eqx.tree_at(lambda p: p.problem.terminal_cost, planner, value, is_leaf=_none)
    return eqx.tree_at(lambda p: p.warm_policy, planner, policy, is_leaf=_none)


def _none(x: Any) -> bool:
    return x is None


def closed_loop_loss(planner: Planner, starts: Float[Array, "B d"], steps: int) -> Array:
    """Minus the mean return of closed-loop episodes of ``steps`` steps from ``starts`` in the
    planner's model: the loss ``learn_value`` differentiates through the planner."""
    returns = jax.vmap(lambda x: planner.episode(x, steps)[2].sum())(starts)
    return -jnp.mean(returns)


@eqx.filter_jit
def _rollouts(planner: Planner, starts: Array, steps: int):
    """Episodes from ``starts``: the states, the running costs, the returns, the finite flags."""
    xs, us, rewards, infos = jax.vmap(lambda x: planner.episode(x, steps))(starts)
    costs = jax.vmap(jax.vmap(planner.problem.running_cost))(xs[:, :-1], us)
    return xs, costs, rewards.sum(1), infos.finite, infos.cost


@eqx.filter_jit
def _fit(value, opt_state, optimizer, states, labels, key, steps: int, batch: int):
    """``steps`` Adam steps of the squared error (in the network's unit) on minibatches."""

    def loss(v, x, y):
        return jnp.mean(((jax.vmap(v)(x) - y) / v.scale) ** 2)

    def one(carry, k):
        v, s = carry
        idx = jax.random.randint(k, (batch,), 0, states.shape[0])
        err, grads = eqx.filter_value_and_grad(loss)(v, states[idx], labels[idx])
        updates, s = optimizer.update(grads, s, eqx.filter(v, eqx.is_inexact_array))
        return (eqx.apply_updates(v, updates), s), err

    (value, opt_state), errs = jax.lax.scan(one, (value, opt_state), jax.random.split(key, steps))
    return value, opt_state, errs


@eqx.filter_jit
def _through_planner_step(trainable, opt_state, optimizer, planner, starts, steps: int):
    """One Adam step on ``closed_loop_loss`` in the trainable networks, through the planner."""

    def loss(t):
        return closed_loop_loss(_install(planner, t), starts, steps)

    value, grads = eqx.filter_value_and_grad(loss)(trainable)
    params = eqx.filter(trainable, eqx.is_inexact_array)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    return eqx.apply_updates(trainable, updates), opt_state, value, optax.tree.norm(grads)


@dataclasses.dataclass
class ValueResult:
    """What ``learn_value`` returns.

    Attributes:
        planner: the planner with the best value network (and warm policy) installed.
        value: that network (``value.to_json()``; ``save``).
        init_value: the best network of the initialisation alone (before the end-to-end steps).
        metrics: settings, the curve (one point per round and per evaluation), seconds.
    """

    planner: Planner
    value: ValueNetwork
    init_value: ValueNetwork
    metrics: dict[str, Any]

    def save(self, path: str | Path) -> None:
        """Write the value network as plain JSON (``load_value`` reads it back)."""
        Path(path).write_text(json.dumps(self.value.to_json()) + "\n")


def load_value(task: Any, path: str | Path) -> ValueNetwork:
    """The ``ValueNetwork`` of ``task`` that ``ValueResult.save`` wrote."""
    return ValueNetwork.from_json(task, json.loads(Path(path).read_text()))


def _count(name: str, value: Any, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < least:
        raise ConfigError(f"{name}={value!r} must be an integer >= {least}")
    return int(value)


def _positive(name: str, value: Any) -> float:
    x = float(value) if isinstance(value, int | float) and not isinstance(value, bool) else math.nan
    if not (math.isfinite(x) and x > 0):
        raise ConfigError(f"{name}={value!r} must be a finite number > 0")
    return x


def learn_value(
    task: Any,
    planner: Planner,
    value: ValueNetwork | None = None,
    *,
    hidden: tuple[int, ...] = (64, 64),
    init_rounds: int = 4,
    episodes: int = 64,
    fit_steps: int = 3000,
    fit_learning_rate: float = 3e-3,
    target: str = "plan",
    steps: int = 30,
    batch: int = 16,
    window: int | None = None,
    learning_rate: float = 3e-4,
    gradient: str = "implicit",
    eval_every: int = 5,
    eval_episodes: int = 64,
    starts: Float[Array, "B d"] | None = None,
    keep_best: bool = True,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> ValueResult:
    """Learn ``planner``'s terminal cost, a ``ValueNetwork``, and its ``warm_policy`` where it
    has one (see the module docstring).

    Args:
        task: the planner's task (a discrete-time ``Task``).
        planner: from ``mpc.make_planner``; its own terminal cost drives the first rollouts
            when ``value`` is ``None``.
        value: the network to start from; default a new ``ValueNetwork(hidden)`` whose unit and
            input normalisation come from the first rollouts.
        hidden: the default network's hidden widths.
        init_rounds: rounds of fitted value iteration (0: the end-to-end stage alone, which
            then needs ``value``).
        episodes: rollouts per round (from ``task.reset``), each ``task.episode_length`` steps.
        fit_steps: Adam steps of the regression per round (``fit_learning_rate``).
        target: the label of a visited state (each round fits the states of its own
            rollouts only, the values of the planner as it now is):
            ``"rollout"``, its cost-to-go along the rollout (to the episode's end, plus the
            network's value of the last state); ``"plan"``, the cost of the plan the planner
            made there (H steps and the network's value of the plan's end: a Bellman backup
            over H steps, fitted value iteration; the default); ``"best"``, the lower of the two.
            The first round, when there is no network yet, takes the rollout's.
        steps: Adam steps through the planner (0: the initialisation alone).
        batch: start states per step (fresh draws from ``task.reset`` each step, or ``starts``).
        window: steps of each closed-loop episode of the loss (default the episode length): a
            truncated window is cheaper and ignores the costs after it.
        learning_rate: Adam's step size through the planner (gradients clipped to norm 1).
        gradient: ``"implicit"`` or ``"unroll"``, how the loss is differentiated through each
            plan (a warm-start policy is only reached by ``"unroll"``).
        eval_every: through-planner steps between evaluations (and at the last step).
        eval_episodes: simulated episodes of each evaluation (the same starts every time).
        starts: a fixed batch of start states for every through-planner step instead.
        keep_best: return the network of the best evaluation (else the last step's; the
            end-to-end stage starts from the best of the initialisation either way).
        seed: PRNG seed: the run is a function of it.
        progress: called with one line per round and per evaluation.

    Raises:
        ConfigError: a count out of range, a non-positive learning rate, an unknown gradient,
            a planner of another task, neither ``value`` nor initialisation rounds.
    """
    init_rounds = _count("init_rounds", init_rounds, 0)
    episodes, fit_steps = _count("episodes", episodes, 1), _count("fit_steps", fit_steps, 1)
    steps, batch = _count("steps", steps, 0), _count("batch", batch, 1)
    eval_every, seed = _count("eval_every", eval_every, 1), _count("seed", seed, 0)
    eval_episodes = _count("eval_episodes", eval_episodes, 1)
    length = task.episode_length
    window = length if window is None else _count("window", window, 1)
    lr, fit_lr = (
        _positive("learning_rate", learning_rate),
        _positive("fit_learning_rate", fit_learning_rate),
    )
    if target not in TARGETS:
        raise ConfigError(f"target={target!r} is not one of {TARGETS}")
    if gradient not in GRADIENTS:
        raise ConfigError(f"gradient={gradient!r} is not one of {GRADIENTS}")
    if not isinstance(planner, Planner):
        raise ConfigError(f"planner={planner!r} is not a Planner; build one with mpc.make_planner")
    if planner.task is not task and planner.task.name != task.name:
        raise ConfigError(f"the planner plans for task {planner.task.name!r}, not {task.name!r}")
    if value is None and init_rounds == 0:
        raise ConfigError("init_rounds=0 needs a value network to start from: pass value=...")
    if value is not None and not isinstance(value, ValueNetwork):
        raise ConfigError(f"value={value!r} is not an mpc.ValueNetwork")

    say = progress or (lambda line: None)
    t_start = time.perf_counter()
    params = planner.problem.params
    forward = dataclasses.replace(planner, gradient="unroll")  # rollouts: no implicit Hessians
    k_net, k_eval, k_run = jax.random.split(jax.random.PRNGKey(seed), 3)
    reset = jax.vmap(task.reset, in_axes=(0, None))
    eval_starts = reset(jax.random.split(k_eval, eval_episodes), params)
    policy = planner.warm_policy
    curve: list[dict[str, Any]] = []

    def evaluate(trainable, stage, **extra):
        returns = np.asarray(_rollouts(_install(forward, trainable), eval_starts, length)[2])
        point = {"stage": stage, "eval_return": float(returns.mean()),
                 "seconds": time.perf_counter() - t_start, **extra}  # fmt: skip
        curve.append(point)
        return point

    best = None
    if value is not None:
        first = evaluate((value, policy), "start")
        best = (first["eval_return"], (value, policy))
        say(f"start: simulated return {first['eval_return']:.2f}")

    # Stage 1: fitted value iteration on the planner's own rollouts.
    fit_opt = optax.adam(fit_lr)
    current = forward if value is None else _install(forward, (value, policy))
    for r in range(init_rounds):
        k_run, k_starts, k_fit = jax.random.split(k_run, 3)
        round_starts = reset(jax.random.split(k_starts, episodes), params)
        xs, costs, returns, finite, planned = _rollouts(current, round_starts, length)
        tail = jax.vmap(current.problem.final_cost)(xs[:, -1])
        to_go = jnp.flip(jnp.cumsum(jnp.flip(costs, 1), 1), 1) + tail[:, None]
        if target != "rollout" and value is not None:  # the planner's own H-step backup
            to_go = planned if target == "plan" else jnp.minimum(to_go, planned)
        states = xs[:, :-1].reshape(-1, xs.shape[-1])
        labels = to_go.reshape(-1)
        if value is None:  # the unit and the input's normalisation from the first data
            obs = np.asarray(jax.vmap(task.observe)(states))
            unit = float(np.mean(np.abs(np.asarray(labels)))) or 1.0
            value = ValueNetwork(k_net, task, hidden, scale=unit,
                                 offset=obs.mean(0), spread=np.maximum(obs.std(0), 1e-3))  # fmt: skip
        opt_state = fit_opt.init(eqx.filter(value, eqx.is_inexact_array))
        value, _, errs = _fit(value, opt_state, fit_opt, states, labels, k_fit, fit_steps, 256)
        current = _install(forward, (value, policy))
        point = evaluate((value, policy), "init", round=r, rollout_return=float(returns.mean()),
                         fit_error=float(np.sqrt(np.mean(np.asarray(errs)[-100:]))),
                         non_finite=int(np.sum(~np.asarray(finite))))  # fmt: skip
        if best is None or point["eval_return"] > best[0]:
            best = (point["eval_return"], (value, policy))
        say(f"init round {r + 1}/{init_rounds}: rollouts {point['rollout_return']:.2f}, fit "
            f"error {point['fit_error']:.4f} (of {value.scale:.1f}), simulated return "
            f"{point['eval_return']:.2f}  {point['seconds']:.1f} s")  # fmt: skip
    init_best = best
    init_seconds = time.perf_counter() - t_start

    # Stage 2: Adam on the closed-loop loss, differentiated through every plan.
    through = dataclasses.replace(planner, gradient=gradient)
    # Clipped: near a plan whose Hessian is nearly singular the implicit derivative can be huge;
    # a non-finite gradient skips the step rather than poisoning Adam's moments.
    optimizer = optax.apply_if_finite(
        optax.chain(optax.clip_by_global_norm(1.0), optax.adam(lr)), max_consecutive_errors=20
    )
    trainable = best[1]
    opt_state = optimizer.init(eqx.filter(trainable, eqx.is_inexact_array))
    for i in range(steps):
        k_run, k_batch = jax.random.split(k_run)
        batch_starts = (
            starts if starts is not None else reset(jax.random.split(k_batch, batch), params)
        )
        trainable, opt_state, loss, norm = _through_planner_step(
            trainable, opt_state, optimizer, through, jnp.asarray(batch_starts), window
        )
        if (i + 1) % eval_every == 0 or i + 1 == steps:
            point = evaluate(trainable, "through planner", step=i + 1, loss=float(loss),
                             gradient_norm=float(norm))  # fmt: skip
            if point["eval_return"] > best[0]:
                best = (point["eval_return"], trainable)
            say(f"step {i + 1}/{steps}: batch loss {float(loss):.2f}, |grad| {float(norm):.3g}, "
                f"simulated return {point['eval_return']:.2f}  {point['seconds']:.1f} s")  # fmt: skip

    metrics = {
        "task": task.name,
        "seed": seed,
        "settings": {
            "target": target,
            "hidden": list(best[1][0].hidden),
            "init_rounds": init_rounds,
            "episodes": episodes,
            "fit_steps": fit_steps,
            "fit_learning_rate": fit_lr,
            "steps": steps,
            "batch": batch,
            "window": window,
            "learning_rate": lr,
            "gradient": gradient,
            "eval_episodes": eval_episodes,
            "horizon": planner.horizon,
        },  # fmt: skip
        "init_eval_return": init_best[0],
        "final_eval_return": best[0],
        "init_seconds": init_seconds,
        "train_seconds": time.perf_counter() - t_start,
        "curve": curve,
    }
    value_best, policy_best = best[1] if keep_best else trainable
    return ValueResult(
        planner=_install(planner, (value_best, policy_best)),
        value=value_best,
        init_value=init_best[1][0],
        metrics=metrics,
    )
