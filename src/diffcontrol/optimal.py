"""A reference optimum for tasks with a small state: finite-horizon dynamic programming on a grid.

For a task whose ``state_grid`` hook returns a grid (Pendulum's ``(theta, theta_dot)``), the
value of every grid point is computed backwards over the episode,

    V_T(x) = 0,     V_t(x) = max_a  r(x, a) + (1 - terminated(x, a)) V_{t+1}(f(x, a)),

with the task's own ``step`` (``f``, ``r``: for Pendulum Gymnasium's dynamics and reward), the
actions ``a`` on an even grid between the task's action bounds, and ``V_{t+1}`` between grid
points by multilinear (for two dimensions bilinear) interpolation. The greedy controller
``a_t(x) = argmax_a r(x, a) + V_{t+1}(f(x, a))`` at the true, off-grid state is an achievable
controller, so its return on the exact dynamics is a lower bound on the best mean return; the
value table's own prediction ``V_0`` converges to the same figure as the grid is refined
(docs/planning.md has Pendulum-v1's). ``solve(..., final=...)`` values the end otherwise.

Everything runs under ``jit``: one ``lax.scan`` over time, inside it one over the actions (a
running maximum, so memory is a few arrays of the grid's size whatever the number of actions),
each a vectorised step of every grid point. It runs on CPU and GPU unchanged.

    table = solve(task, points=801, levels=41)
    result = optimal_return(task, seeds=range(100), table=table)   # Gymnasium episodes
"""

from __future__ import annotations

import collections
import dataclasses
import itertools
import math
from collections.abc import Iterable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PyTree

from . import _fingerprint, _gym, _jax_setup
from .errors import ConfigError
from .evaluation import eval_environment
from .tasks._grid import GridAxis

__all__ = ["GridAxis", "OptimumResult", "ValueTable", "greedy_rollout", "optimal_return", "solve"]


class ValueTable(eqx.Module):
    """The values ``V_t`` of a task on a state grid, ``t = 0 ... horizon`` (``V_horizon = 0``),
    and the greedy controller they define.

    Attributes:
        values: ``[horizon + 1, n_1, ..., n_d]``, the value (the best return to go) at each
            grid point and time.
        actions: ``[levels^m, m]``, the action grid the values were maximised over.
        params: the physical parameters the task was solved with.
    """

    values: Float[Array, "T1 ..."]
    actions: Float[Array, "A m"]
    params: PyTree
    task: Any = eqx.field(static=True)
    axes: tuple[GridAxis, ...] = eqx.field(static=True)

    @property
    def horizon(self) -> int:
        return self.values.shape[0] - 1

    def value(self, t: Array | int, state: Float[Array, " d"]) -> Array:
        """``V_t(state)``, interpolated between grid points."""
        return _interpolate(self.values[t], self.axes, state)

    def q_values(self, t: Array | int, state: Float[Array, " d"]) -> Float[Array, " A"]:
        """``r(state, a) + V_{t+1}(f(state, a))`` for every action of the grid, at the exact
        (off-grid) state."""
        v_next = self.values[jnp.minimum(t + 1, self.horizon)]

        def q(action):
            nxt, reward, terminated = self.task.step(self.params, state, action)
            future = _interpolate(v_next, self.axes, nxt)
            return reward + jnp.where(terminated | (t + 1 > self.horizon), 0.0, future)

        return jax.vmap(q)(self.actions)

    def action(self, t: Array | int, state: Float[Array, " d"]) -> Float[Array, " m"]:
        """The greedy action at time ``t`` (steps since the reset) in ``state``."""
        return self.actions[jnp.argmax(self.q_values(t, state))]


def _axis_points(axis: GridAxis, n: int) -> np.ndarray:
    if axis.periodic:
        return axis.low + (axis.high - axis.low) * np.arange(n) / n
    return np.linspace(axis.low, axis.high, n)


def _interpolate(values: Array, axes: Sequence[GridAxis], state: Array) -> Array:
    """Multilinear interpolation of ``values`` (one entry per grid point) at ``state``: a
    periodic axis wraps, a bounded one clamps to its edge."""
    lower, frac = [], []
    for k, axis in enumerate(axes):
        n = values.shape[k]
        if axis.periodic:
            c = jnp.mod((state[k] - axis.low) / (axis.high - axis.low) * n, n)
            i0 = jnp.minimum(jnp.floor(c).astype(jnp.int32), n - 1)
            lower.append((i0, (i0 + 1) % n))
        else:
            c = jnp.clip((state[k] - axis.low) / (axis.high - axis.low) * (n - 1), 0, n - 1)
            i0 = jnp.minimum(jnp.floor(c).astype(jnp.int32), n - 2)
            lower.append((i0, i0 + 1))
        frac.append(c - i0)
    total = 0.0
    for corner in itertools.product((0, 1), repeat=len(axes)):
        weight = 1.0
        for k, side in enumerate(corner):
            weight = weight * (frac[k] if side else 1.0 - frac[k])
        total = total + weight * values[tuple(lower[k][side] for k, side in enumerate(corner))]
    return total


def _action_grid(task: Any, levels: int) -> np.ndarray:
    if task.action_low is None or task.action_high is None:
        raise ConfigError(
            f"task {task.name!r} has no action bounds (action_low/action_high), so its actions "
            "cannot be gridded for the reference optimum"
        )
    per_dim = [np.linspace(lo, hi, levels) for lo, hi in zip(task.action_low, task.action_high)]
    return np.array(list(itertools.product(*per_dim)), np.float32)


def _check_grid(task: Any, params: PyTree, points: int | Sequence[int], levels: int):
    axes = task.state_grid(params) if hasattr(task, "state_grid") else None
    if axes is None:
        raise ConfigError(
            f"task {task.name!r} offers no state grid (its state_grid hook returns None), so it "
            "has no reference optimum; define state_grid for a task with a small state"
        )
    state = jax.eval_shape(task.reset, jax.random.PRNGKey(0), params)
    if len(axes) != int(np.prod(state.shape)):
        raise ConfigError(
            f"task {task.name!r}: its state_grid has {len(axes)} axes for a state of "
            f"{int(np.prod(state.shape))} entries; give one GridAxis per entry of the state"
        )
    sizes = (points,) * len(axes) if isinstance(points, int) else tuple(points)
    if len(sizes) != len(axes) or any(int(n) < 3 for n in sizes):
        raise ConfigError(
            f"points={points!r} must be one int >= 3 or one per state axis ({len(axes)}) each >= 3"
        )
    if int(levels) < 2:
        raise ConfigError(f"levels={levels!r} must be >= 2 (actions per action dimension)")
    return tuple(axes), tuple(int(n) for n in sizes)


def solve(
    task: Any,
    points: int | Sequence[int] = 801,
    levels: int = 41,
    params: PyTree | None = None,
    horizon: int | None = None,
    final: Any = None,
) -> ValueTable:
    """Solve ``task`` by finite-horizon dynamic programming on its ``state_grid``.

    Args:
        task: a ``Task`` whose ``state_grid`` hook returns a grid and that has action bounds.
        points: grid points per state axis (one int for all, or one per axis).
        levels: actions per action dimension, evenly from ``action_low`` to ``action_high``.
        params: physical parameters (default ``task.default_params()``).
        horizon: steps (default ``task.episode_length``).
        final: ``V_horizon(params, state)``, the value of ending in a state (default 0).

    Returns:
        The ``ValueTable`` (``V_0 ... V_horizon``; about ``4 (horizon+1) prod(points)`` bytes).

    Raises:
        ConfigError: the task has no grid or no action bounds, or a size is out of range (a
            table of more than ``MAX_TABLE`` values).
    """
    params = task.default_params() if params is None else params
    axes, sizes = _check_grid(task, params, points, levels)
    horizon = task.episode_length if horizon is None else int(horizon)
    if horizon < 1:
        raise ConfigError(f"horizon={horizon} must be >= 1 (steps to plan over)")
    if (horizon + 1) * math.prod(sizes) > MAX_TABLE:
        raise ConfigError(
            f"a grid of {' x '.join(map(str, sizes))} points over {horizon} steps is a table of "
            f"{(horizon + 1) * math.prod(sizes):,} values, more than {MAX_TABLE:,}; choose "
            "fewer points per axis or a shorter horizon"
        )
    actions = jnp.asarray(_action_grid(task, int(levels)))
    mesh = np.meshgrid(*(_axis_points(a, n) for a, n in zip(axes, sizes)), indexing="ij")
    states = jnp.asarray(np.stack([m.ravel() for m in mesh], axis=1), jnp.float32)
    values = _backward(task, params, axes, sizes, states, actions, horizon, final)
    return ValueTable(values, actions, params, task, axes)


MAX_TABLE = 201 * 1001**2
"""The most values ``solve`` holds (every step's grid: ``horizon + 1`` grids): Pendulum's
1001 x 1001 table over 200 steps, 0.8 GB."""


def solve_first(
    task: Any,
    points: int | Sequence[int] = 801,
    levels: int = 41,
    params: PyTree | None = None,
    horizon: int | None = None,
) -> ValueTable:
    """``solve``'s table cut to ``V_0`` (the best return of a whole horizon from each grid
    state: a planner's or a training window's terminal value). Kept in this process for a
    built-in task, by its class and fingerprint, the grid, the horizon and the physics, so that
    training or planning the same task on the same physics again does not solve it again; a
    user's task is solved every time (its step may read what changed since).
    ``forget_solved()`` lets them go."""
    params = task.default_params() if params is None else params
    horizon = task.episode_length if horizon is None else int(horizon)
    ours = type(task).__module__.startswith("diffcontrol.")
    mark = _fingerprint.fingerprint(task) if ours else None
    sizes = tuple(points) if isinstance(points, Sequence) else points
    key = (type(task), mark, sizes, levels, horizon, _fingerprint.physics_key(params))
    if mark is not None and key in _SOLVED:
        _SOLVED.move_to_end(key)
        return _SOLVED[key][1]
    table = solve(task, points, levels, params=params, horizon=horizon)
    first = eqx.tree_at(lambda t: t.values, table, table.values[:1])
    if mark is not None:
        while len(_SOLVED) >= _SOLVED_KEPT:
            _SOLVED.popitem(last=False)
        _SOLVED[key] = (task, first)  # the task held, so that its methods' ids stay its own
    return first


def forget_solved() -> None:
    """Let go of the tables ``solve_first`` keeps."""
    _SOLVED.clear()


_SOLVED: collections.OrderedDict[tuple, tuple[Any, ValueTable]] = collections.OrderedDict()
_SOLVED_KEPT = 4  # Pendulum's V_0 on 201 x 201 points is 160 kB


@_jax_setup.RunningJit  # its sweeps are its cost, not its compiling
def _backward(task, params, axes, sizes, states, actions, horizon, final=None):
    step_all = jax.vmap(task.step, in_axes=(None, 0, None))
    interp_all = jax.vmap(_interpolate, in_axes=(None, None, 0))

    def backup(v_next, _):
        grid_v = v_next.reshape(sizes)

        def best_of(best, action):
            nxt, reward, terminated = step_all(params, states, action)
            q = reward + jnp.where(terminated, 0.0, interp_all(grid_v, axes, nxt))
            return jnp.maximum(best, q), None

        v, _ = jax.lax.scan(best_of, jnp.full(states.shape[0], -jnp.inf), actions)
        return v, v

    if final is None:
        final = jnp.zeros(states.shape[0])
    else:
        final = jax.vmap(final, in_axes=(None, 0))(params, states).astype(states.dtype)
    _, earlier = jax.lax.scan(backup, final, None, length=horizon)
    # earlier[k] is V_{horizon-1-k}: reverse it and append V_horizon.
    return jnp.concatenate([earlier[::-1], final[None]]).reshape((horizon + 1, *sizes))


@eqx.filter_jit
def greedy_rollout(table: ValueTable, starts: Float[Array, "B d"]) -> Float[Array, " B"]:
    """Returns of the greedy controller over ``table.horizon`` steps of the task's own
    simulator from each of ``starts`` (a batch of states)."""

    def episode(state):
        def one(carry, t):
            state, done = carry
            nxt, reward, terminated = table.task.step(table.params, state, table.action(t, state))
            return (nxt, done | terminated), jnp.where(done, 0.0, reward)

        _, rewards = jax.lax.scan(one, (state, jnp.asarray(False)), jnp.arange(table.horizon))
        return rewards.sum()

    return jax.vmap(episode)(starts)


@dataclasses.dataclass
class OptimumResult:
    """The greedy controller of a value table in Gymnasium episodes with the given reset seeds,
    next to what the table predicts (``V_0`` at the same starts)."""

    env_id: str
    seeds: list[int]
    returns: np.ndarray
    predicted: np.ndarray
    points: tuple[int, ...]
    levels: int

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def predicted_mean(self) -> float:
        return float(np.mean(self.predicted))

    def gap(self, mean_return: float) -> float:
        """How far ``mean_return`` is below this optimum, as a fraction of its size."""
        return (self.mean - mean_return) / abs(self.mean)

    def to_json(self) -> dict[str, Any]:
        return {
            "env_id": self.env_id,
            "seeds": [self.seeds[0], self.seeds[-1]],
            "episodes": len(self.seeds),
            "grid_points": list(self.points),
            "action_levels": self.levels,
            "mean_return": self.mean,
            "predicted_mean": self.predicted_mean,
            "returns": self.returns.tolist(),
        }

    def summary(self) -> str:
        grid = " x ".join(map(str, self.points))
        return (
            f"{self.env_id} optimum (grid {grid}, {self.levels} actions): greedy return "
            f"{self.mean:.2f} on seeds {self.seeds[0]}-{self.seeds[-1]} (value predicts "
            f"{self.predicted_mean:.2f})"
        )


def optimal_return(
    task: Any,
    seeds: Iterable[int] = range(100),
    points: int | Sequence[int] = 801,
    levels: int = 41,
    table: ValueTable | None = None,
    *,
    params: PyTree | None = None,
    real: tuple[str, dict | None] | None = None,
) -> OptimumResult:
    """The reference optimum of ``task`` on Gymnasium reset seeds: the greedy controller of
    the grid dynamic program (``solve``, or the given ``table``) run in the task's Gymnasium
    environment (``make_gym_env``, for Pendulum Gymnasium's own ``Pendulum-v1``), all
    episodes in lockstep with one batched controller call per step.

    The controller sees Gymnasium's observations and recovers the state with
    ``state_from_observation``; the returns are Gymnasium's rewards.

    Args:
        params: the physical parameters to solve with (default the task's nominal ones);
            ignored with ``table`` (solved with its own).
        real: ``(env_id, env_kwargs)`` of another Gymnasium environment to run the episodes
            in, the system ``params`` describe (e.g. ``("diffcontrol/PendulumFriction-v0",
            {"g": 12.0, "friction": 0.1})`` with ``params_of_env`` of the same), as
            ``evaluation.evaluate``'s ``real``; the optimum is then that system's.
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ConfigError("seeds is empty; pass at least one Gymnasium reset seed")
    table = solve(task, points, levels, params=params) if table is None else table
    act = jax.jit(jax.vmap(table.action, in_axes=(None, 0)))
    value = jax.jit(jax.vmap(table.value, in_axes=(None, 0)))
    to_state = jax.jit(jax.vmap(_gym.state_from_observation.bound(task)))
    envs, labels = zip(*(eval_environment(task, real) for _ in seeds))
    try:
        obs = np.stack([env.reset(seed=s)[0] for env, s in zip(envs, seeds)])
        predicted = np.asarray(value(0, to_state(jnp.asarray(obs))))
        returns = np.zeros(len(seeds))
        running = np.ones(len(seeds), bool)
        for t in range(table.horizon):
            actions = np.asarray(act(t, to_state(jnp.asarray(obs))))
            for i, env in enumerate(envs):
                if not running[i]:
                    continue
                obs[i], reward, terminated, truncated, _ = env.step(
                    _gym.gym_action(task, actions[i])
                )
                returns[i] += float(reward)
                running[i] = not (terminated or truncated)
            if not running.any():
                break
    finally:
        for env in envs:
            env.close()
    sizes = tuple(table.values.shape[1:])
    return OptimumResult(labels[0], seeds, returns, predicted, sizes, len(table.actions))
