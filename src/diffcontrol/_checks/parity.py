"""Parity of a task's ``step`` with its Gymnasium twin, step by step from the same states
(``diffcontrol.check_task``).

The general form of the comparison ``tests/test_systems_vs_gymnasium.py`` runs for the
built-in tasks: any task whose twin can be put into one of its states (``_gym.set_gym_state``)
is checked the same way, by ``diffcontrol.check_task``.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PyTree

from .. import _gym
from ..errors import TaskCheckError
from ..tasks import Task
from .util import ACTION_SCALE, fail, fmt, valid_action


def check_parity(
    task: Task,
    params: PyTree,
    env_id: str | None,
    env_kwargs: dict[str, Any],
    *,
    states: int,
    steps: int,
    seed: int,
    rtol: float,
    atol: float,
) -> tuple[str, int, dict[str, float]]:
    """Compare ``task.step`` with the twin's ``env.step`` (see ``check_task``).

    Returns:
        The twin's id, how many steps were compared, and the largest absolute differences of
        the observation and the reward.

    Raises:
        TaskCheckError: the first step where the observation, the reward or the termination
            differ beyond the tolerance, or the twin rejects the task's action.
    """
    env = gymnasium.make(env_id, **env_kwargs) if env_id else _gym.make_gym_env(task, **env_kwargs)
    label = env_id or task.gym_id
    try:
        return label, *_compare(task, params, env, label, states, steps, seed, rtol, atol)
    finally:
        env.close()


def _trajectories(task: Task, params: PyTree, states: int, steps: int, seed: int):
    """``steps`` steps from ``states`` reset states with random valid actions (one program)."""

    @jax.jit
    def run(key, params):
        # One compiled program: eager JAX would compile every operation.
        k_reset, k_action = jax.random.split(key)
        s0 = jax.vmap(task.reset, (0, None))(jax.random.split(k_reset, states), params)
        shape = (states, steps, task.action_size)
        raw = ACTION_SCALE * jax.random.normal(k_action, shape, s0.dtype)

        def one(s0, raw):
            def body(carry, raw):
                state, alive = carry
                action = valid_action(task, raw)
                next_state, reward, terminated = task.step(params, state, action)
                out = (state, action, task.observe(next_state), reward, terminated, alive)
                return (next_state, alive & ~terminated), out

            return jax.lax.scan(body, (s0, jnp.asarray(True)), raw)[1]

        return jax.vmap(one)(s0, raw)

    return [np.asarray(x) for x in run(jax.random.PRNGKey(seed + 1), params)]


def _compare(task, params, env, label, states, steps, seed, rtol, atol):
    name = type(task).__name__
    s, a, obs, reward, term, alive = _trajectories(task, params, states, steps, seed)
    errors = {"observation": 0.0, "reward": 0.0}
    compared = 0
    for i in range(states):
        # A fresh episode for every trajectory: clears the twin's bookkeeping (CartPole's
        # steps_beyond_terminated, the time limit) before its state is set.
        env.reset(seed=seed + i)
        for t in range(steps):
            if not alive[i, t]:
                break
            where = (
                f"from state {fmt(s[i, t])} with action {fmt(a[i, t])} (reset state {i}, step {t})"
            )
            _gym.set_gym_state(task, env, s[i, t])
            action = _gym.gym_action(task, a[i, t])
            try:
                gym_obs, gym_reward, gym_term, _, _ = env.step(action)
            except Exception as e:
                why = (str(e).strip().splitlines() or [""])[0]
                raise TaskCheckError(
                    f"Gymnasium's {label} rejected {name}.gym_action({fmt(a[i, t])}) = "
                    f"{action!r}: {type(e).__name__}: {why}"
                ) from e
            compared += 1
            gym_obs = np.asarray(gym_obs, np.float64)
            if gym_obs.shape != obs[i, t].shape:
                fail(
                    f"Gymnasium's {label} observes shape {gym_obs.shape}, but {name}.observe "
                    f"returns shape {obs[i, t].shape}"
                )
            for what, ours, theirs in (
                ("observation", obs[i, t], gym_obs),
                ("reward", reward[i, t], gym_reward),
            ):
                ours, theirs = np.asarray(ours, np.float64), np.asarray(theirs, np.float64)
                err = np.abs(ours - theirs)
                errors[what] = max(errors[what], float(np.max(err)))
                if not np.all(err <= atol + rtol * np.abs(theirs)):
                    fail(
                        f"{name}.step does not match Gymnasium's {label} on the {what} {where}: "
                        f"{fmt(ours)} against Gymnasium's {fmt(theirs)} (rtol {rtol:g}, "
                        f"atol {atol:g})"
                    )
            if bool(term[i, t]) != bool(gym_term):
                fail(
                    f"{name}.step does not match Gymnasium's {label} on termination {where}: "
                    f"terminated={bool(term[i, t])} against Gymnasium's {bool(gym_term)}"
                )
    return compared, errors
