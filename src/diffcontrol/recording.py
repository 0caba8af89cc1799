"""Recording trajectories from any Gymnasium environment, with a controller or random actions."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from . import __version__
from .data import DISCRETE_UNIT, KNOWN_COLUMNS, TrajectoryData
from .errors import ConfigError
from .io import now_iso


def make_env(env_id: str, env_kwargs: dict | None = None) -> gymnasium.Env:
    """``gymnasium.make(env_id, **env_kwargs)``, with an unknown id as a ``ConfigError``.

    Raises:
        ConfigError: Gymnasium does not know ``env_id`` (the message lists a few it does), or
            refuses ``env_kwargs``.
    """
    try:
        return gymnasium.make(env_id, **(env_kwargs or {}))
    except gymnasium.error.Error as e:
        known = ", ".join(list(KNOWN_COLUMNS)[:4])
        raise ConfigError(
            f"unknown Gymnasium environment {env_id!r} ({' '.join(str(e).split())}); known ones "
            f'include {known}, ... (`python -c "import gymnasium; gymnasium.pprint_registry()"` '
            "lists all)"
        ) from None
    except TypeError as e:
        raise ConfigError(f"{env_id} does not take the arguments {env_kwargs} ({e})") from None


def _time_step(env: gymnasium.Env) -> float | None:
    """The environment's time step (s), where it exposes one (``dt``, ``tau``, or a
    diffcontrol control task's parameters); ``None`` otherwise (time is then in steps)."""
    from .envs import TaskEnv

    u = env.unwrapped
    for name in ("dt", "tau"):
        if isinstance(getattr(u, name, None), int | float):
            return float(getattr(u, name))
    if isinstance(u, TaskEnv):
        return u.task.step_seconds(u.params)
    return None


def columns_for(env_id: str, env: gymnasium.Env) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The observation and action columns of ``env``: the known names and units for the
    environments in ``KNOWN_COLUMNS``, otherwise ``obs.0 [?]``, ... (unknown units),
    ``action.0 [?]`` and ``action.0 [index]`` for a ``Discrete`` action.

    Raises:
        ConfigError: the observation space is not a flat ``Box``, or the action space is not
            a flat ``Box`` or ``Discrete``.
    """
    obs_space, act_space = env.observation_space, env.action_space
    if not isinstance(obs_space, spaces.Box) or len(obs_space.shape) != 1:
        raise ConfigError(
            f"{env_id} has the observation space {obs_space}; recording needs a flat Box "
            "(wrap the environment in gymnasium.wrappers.FlattenObservation)"
        )
    if isinstance(act_space, spaces.Discrete):
        actions: tuple[str, ...] = (f"action.0 [{DISCRETE_UNIT}]",)
    elif isinstance(act_space, spaces.Box) and len(act_space.shape) <= 1:
        actions = tuple(f"action.{j} [?]" for j in range(int(np.prod(act_space.shape))))
    else:
        raise ConfigError(
            f"{env_id} has the action space {act_space}; recording needs a flat Box or Discrete"
        )
    observations = tuple(f"obs.{i} [?]" for i in range(obs_space.shape[0]))
    known = KNOWN_COLUMNS.get(env_id)
    if known and (len(known[0]), len(known[1])) == (len(observations), len(actions)):
        return known
    return observations, actions


def _check_policy(policy: Any, env_id: str, obs_size: int) -> None:
    doc = getattr(policy, "doc", None)
    size = doc.get("observation", {}).get("size") if isinstance(doc, dict) else None
    if size is not None and size != obs_size:
        raise ConfigError(
            f"the controller (task {doc.get('task')!r}, made for {doc.get('gym_id')}) takes "
            f"{size} observations but {env_id} gives {obs_size}; record with a controller "
            f"trained for {env_id}, or without one for random actions"
        )


def _action_row(action: Any, space: spaces.Space, env_id: str) -> np.ndarray:
    """The recorded action vector for a Gymnasium action, refusing one that does not fit."""
    if isinstance(space, spaces.Discrete):
        a = np.asarray(action).reshape(-1)
        if a.size != 1 or not space.contains(int(a[0])) or a[0] != int(a[0]):
            raise ConfigError(
                f"the policy returned {action!r}, not an action of {env_id}'s {space}; give a "
                "policy for this environment"
            )
        return np.array([float(a[0])])
    a = np.asarray(action, np.float64).reshape(-1)
    if a.size != int(np.prod(space.shape)):
        raise ConfigError(
            f"the policy returned {a.size} action value(s) but {env_id} takes "
            f"{int(np.prod(space.shape))}; give a policy for this environment"
        )
    return a


def record(
    env_id: str,
    episodes: int,
    policy: Callable[[np.ndarray], Any] | None = None,
    seed: int = 0,
    env_kwargs: dict | None = None,
    max_steps: int | None = None,
    progress: Callable[[str], None] | None = None,
    source: str | None = None,
) -> TrajectoryData:
    """Record ``episodes`` episodes of ``gymnasium.make(env_id, **env_kwargs)``.

    Episode ``i`` is reset with seed ``seed + i``; each step applies ``policy(obs)`` (e.g.
    ``diffcontrol.load(DIR)``), or, without a policy, a random action from the environment's
    action space seeded once with ``seed``. An episode ends when the environment terminates
    or truncates it (or after ``max_steps``). Observations are stored as float64 (exactly
    the environment's float32 values), actions as given to the environment (before any
    clipping the environment does itself).

    Args:
        env_id: any registered Gymnasium id with a flat ``Box`` observation space and a flat
            ``Box`` or ``Discrete`` action space.
        episodes: how many episodes (>= 1).
        policy: a callable from one observation to a Gymnasium action; None for random.
        seed: the first reset seed, and the seed of the random actions.
        env_kwargs: keyword arguments of ``gymnasium.make`` (e.g. ``{"g": 9.0}``).
        max_steps: the most steps an episode may take; the environment's own limit if None.
        progress: called with a line after every ~5 % of the episodes.
        source: how the actions were chosen, for the metadata (default: ``random actions``
            or ``policy <repr>``).

    Returns:
        The ``TrajectoryData``, with metadata ``env_id``, ``env_kwargs``, ``dt_s``,
        ``seed``, ``source``, ``returns`` and ``ends`` (``terminated``/``truncated``) per
        episode, ``recorded`` and ``diffcontrol_version``.

    Raises:
        ConfigError: ``episodes < 1``, an unknown ``env_id``, spaces that cannot be recorded,
            a policy that does not fit the environment, or an episode with no end.
    """
    if not isinstance(episodes, int) or episodes < 1:
        raise ConfigError(f"episodes must be a positive integer, got {episodes!r}")
    env = make_env(env_id, env_kwargs)
    obs_columns, act_columns = columns_for(env_id, env)
    limit = max_steps or (env.spec.max_episode_steps if env.spec else None)
    if limit is None:
        raise ConfigError(f"{env_id} has no episode step limit; pass max_steps")
    _check_policy(policy, env_id, len(obs_columns))
    if policy is None:
        env.action_space.seed(seed)
    every = max(1, episodes // 20)
    all_obs, all_act, returns, ends = [], [], [], []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed + i)
        observations, actions, total, done = [obs], [], 0.0, False
        while not done:
            action = env.action_space.sample() if policy is None else policy(obs)
            actions.append(_action_row(action, env.action_space, env_id))
            obs, reward, terminated, truncated, _ = env.step(action)
            observations.append(obs)
            total += float(reward)
            done = terminated or truncated or (limit is not None and len(actions) >= limit)
        all_obs.append(np.asarray(observations, np.float64))
        all_act.append(np.stack(actions))
        returns.append(total)
        ends.append("terminated" if terminated else "truncated")
        if progress and ((i + 1) % every == 0 or i + 1 == episodes):
            progress(
                f"episode {i + 1}/{episodes} (seed {seed + i}): {len(actions)} steps, "
                f"return {total:.1f}"
            )
    env.close()
    if source is None:
        source = "random actions" if policy is None else f"policy {policy!r}"
    metadata = {
        "env_id": env_id,
        "env_kwargs": dict(env_kwargs or {}),
        "seed": seed,
        "source": source,
        "returns": [r if np.isfinite(r) else None for r in returns],
        "ends": ends,
        "recorded": now_iso(),
        "diffcontrol_version": __version__,
    }
    return TrajectoryData.from_episodes(
        all_obs, all_act, obs_columns, act_columns, dt_s=_time_step(env), metadata=metadata
    )
