"""Recording trajectories from any Gymnasium environment, with a controller or random actions.

``record(env_id, ...)`` records any environment; with ``task=`` the environment is the real
system of a task (its spaces must match the task's) and the columns are named by the task
(``data_columns``), and without it by the task that names that environment's columns
(``data.known_columns()``). ``record_data(source, ...)`` is ``diffcontrol record``: a task's
own recording (``record_task``: Gymnasium episodes by default; a task may record its own
simulator, e.g. one-step episodes of a single measured outcome) or a plain Gymnasium id,
written to a CSV or NPZ file.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from .. import _gym, io, tasks
from .._version import __version__
from ..envs import TaskEnv, make_env
from ..envs import env_id as own_id
from ..errors import ConfigError, DataFileError
from ..io import now_iso
from ..policies import NumpyPolicy, read_model
from ..settings import RecordConfig
from ..tasks import Task
from ..tasks._hooks import task_hook
from ._task import data_columns, data_file_name, step_seconds
from .data import DISCRETE_UNIT, TrajectoryData, known_columns, write_trajectories


def _time_step(env: gymnasium.Env) -> float | None:
    """The environment's time step (s), where it exposes one (``dt``, ``tau``, or a
    diffcontrol control task's parameters); ``None`` otherwise (time is then in steps)."""
    u = env.unwrapped
    for name in ("dt", "tau"):
        if isinstance(getattr(u, name, None), int | float):
            return float(getattr(u, name))
    if isinstance(u, TaskEnv):
        return step_seconds(u.task, u.params)
    return None


def columns_for(env_id: str, env: gymnasium.Env) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The observation and action columns of ``env``: the names and units a registered task
    gives them (``known_columns()``), otherwise ``obs.0 [?]``, ... (unknown units),
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
    known = known_columns().get(env_id)
    if known and (len(known[0]), len(known[1])) == (len(observations), len(actions)):
        return known
    return observations, actions


def check_spaces(task: Any, env_id: str, env: gymnasium.Env) -> None:
    """Refuse an environment whose spaces are not the task's (observation size, action space).

    Raises:
        ConfigError: the spaces differ (naming both).
    """
    obs, act = env.observation_space, env.action_space
    want = _gym.action_space(task)
    same_obs = isinstance(obs, spaces.Box) and obs.shape == (task.observation_size,)
    if isinstance(want, spaces.Discrete):
        same_act = isinstance(act, spaces.Discrete) and act.n == want.n
    else:
        same_act = isinstance(act, spaces.Box) and act.shape == want.shape
    if not (same_obs and same_act):
        raise ConfigError(
            f"{env_id} has the spaces {obs} and {act}, but task {task.name!r} takes "
            f"{task.observation_size} observations and {want}; record an environment with "
            "the task's spaces, or choose the task that fits it"
        )


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
    episodes: int | None,
    policy: Callable[[np.ndarray], Any] | None = None,
    seed: int = 0,
    env_kwargs: dict | None = None,
    max_steps: int | None = None,
    progress: Callable[[str], None] | None = None,
    source: str | None = None,
    task: Any = None,
    total_steps: int | None = None,
    skip_seeds: range = range(0),
) -> TrajectoryData:
    """Record ``episodes`` episodes of ``gymnasium.make(env_id, **env_kwargs)``, or episodes
    until a budget of ``total_steps`` transitions is spent.

    Episode ``i`` is reset with seed ``seed + i`` (counting on past ``skip_seeds``); each step
    applies ``policy(obs)`` (e.g. ``diffcontrol.load(DIR)``), or, without a policy, a random
    action from the environment's action space seeded once with ``seed``. An episode ends when
    the environment terminates or truncates it (or after ``max_steps``, or when the
    ``total_steps`` budget is spent: the last episode is cut short there and ends as
    ``truncated``). Observations are stored as float64 (exactly the environment's float32
    values), actions as given to the environment (before any clipping the environment does
    itself).

    Args:
        env_id: any registered Gymnasium id with a flat ``Box`` observation space and a flat
            ``Box`` or ``Discrete`` action space.
        episodes: how many episodes (>= 1); with ``total_steps``, the most episodes, or None for as
            many as the budget takes (a CartPole episode of random pushes lasts ~20 steps).
        policy: a callable from one observation to a Gymnasium action; None for random. One
            with a ``reset()`` (a planner, warm-started from its last plan) is reset before
            every episode.
        seed: the first reset seed, and the seed of the random actions.
        env_kwargs: keyword arguments of ``gymnasium.make`` (e.g. ``{"g": 9.0}``).
        max_steps: the most steps an episode may take; the environment's own limit if None.
        progress: called with a line after every ~5 % of the episodes.
        source: how the actions were chosen, for the metadata (default: ``random actions``
            or ``policy <repr>``).
        task: the task whose real system ``env_id`` is: its spaces must match the task's,
            and the columns are the task's ``data_columns()``.
        total_steps: a budget of transitions in all (>= 1): recording stops once it is spent, so
            that the real system's time, not its episodes, is what is asked for.
        skip_seeds: reset seeds not to record from (an evaluation's, so that a model is never
            fitted to episodes from the starts its controller is judged on).

    Returns:
        The ``TrajectoryData``, with metadata ``env_id``, ``env_kwargs``, ``dt_s``,
        ``seed``, ``source``, ``returns`` and ``ends`` (``terminated``/``truncated``) per
        episode, ``recorded`` and ``diffcontrol_version``.

    Raises:
        ConfigError: ``episodes < 1``, an unknown ``env_id``, spaces that cannot be recorded,
            a policy that does not fit the environment, or an episode with no end.
    """
    for name, value in (("episodes", episodes), ("total_steps", total_steps)):
        if value is not None and (not isinstance(value, int) or value < 1):
            raise ConfigError(f"{name} must be a positive integer, got {value!r}")
    if episodes is None and total_steps is None:
        raise ConfigError("record needs a number of episodes or a budget of steps; give one")
    # each episode takes at least one step, so a budget alone bounds the episodes
    episodes = total_steps if episodes is None else episodes
    env = make_env(env_id, env_kwargs)
    obs_columns, act_columns = columns_for(env_id, env)
    if task is not None:
        check_spaces(task, env_id, env)
        obs_columns, act_columns = data_columns(task)
    limit = max_steps or (env.spec.max_episode_steps if env.spec else None)
    if limit is None:
        raise ConfigError(f"{env_id} has no episode step limit; pass max_steps")
    _check_policy(policy, env_id, len(obs_columns))
    if policy is None:
        env.action_space.seed(seed)
    every = max(1, (episodes if total_steps is None else max(1, total_steps // limit)) // 20)
    all_obs, all_act, returns, ends = [], [], [], []
    left = total_steps  # the budget's transitions still to record (None: no budget)
    reset_seeds = (s for s in itertools.count(seed) if s not in skip_seeds)
    for i in range(episodes):
        if left == 0:
            break
        reset_seed = next(reset_seeds)
        obs, _ = _call(env.reset, env_id, i, 0, seed=reset_seed)
        if callable(getattr(policy, "reset", None)):  # a planner starts each episode afresh
            policy.reset()
        observations, actions, total, done = [obs], [], 0.0, False
        while not done:
            _check_finite(obs, env_id, i, len(actions))
            action = env.action_space.sample() if policy is None else policy(obs)
            actions.append(_action_row(action, env.action_space, env_id))
            obs, reward, terminated, truncated, _ = _call(env.step, env_id, i, len(actions), action)
            _check_step(obs, reward, env.observation_space, env_id, i, len(actions))
            observations.append(obs)
            total += float(reward)
            left = None if left is None else left - 1
            done = terminated or truncated or len(actions) >= limit or left == 0
        _check_finite(obs, env_id, i, len(actions))
        all_obs.append(np.asarray(observations, np.float64))
        all_act.append(np.stack(actions))
        returns.append(total)
        ends.append("terminated" if terminated else "truncated")
        if progress and ((i + 1) % every == 0 or i + 1 == episodes or left == 0):
            of = (
                f"/{episodes}"
                if total_steps is None
                else f" ({total_steps - left}/{total_steps} steps)"
            )
            progress(
                f"episode {i + 1}{of} (seed {reset_seed}): {len(actions)} steps, return {total:.1f}"
            )
    env.close()
    if source is None:
        source = "random actions" if policy is None else f"policy {policy!r}"

    metadata = {
        "env_id": env_id,
        "env_kwargs": dict(env_kwargs or {}),
        "seed": seed,
        **({"skipped_seeds": [skip_seeds.start, skip_seeds.stop]} if skip_seeds else {}),
        "source": source,
        "returns": [r if np.isfinite(r) else None for r in returns],
        "ends": ends,
        "recorded": now_iso(),
        "diffcontrol_version": __version__,
    }
    return TrajectoryData.from_episodes(
        all_obs, all_act, obs_columns, act_columns, dt_s=_time_step(env), metadata=metadata
    )


def _call(method: Callable, env_id: str, episode: int, step: int, *args: Any, **kw: Any) -> Any:
    """``env.reset``/``env.step``, with an exception of the environment turned into one line
    (the environment is the user's: a bug there is not diffcontrol's traceback)."""
    try:
        return method(*args, **kw)
    except (KeyboardInterrupt, SystemExit, ConfigError):
        raise
    except Exception as e:
        raise ConfigError(
            f"{env_id} raised {type(e).__name__}: {e} in episode {episode} at step {step} while "
            "recording; nothing of this recording was written: fix the environment and record again"
        ) from None


def _check_step(obs: Any, reward: Any, space: Any, env_id: str, episode: int, step: int) -> None:
    """Refuse a step that breaks the environment's own space (an observation of another
    shape) or gives a reward that is not a finite number: the system is not what it says."""
    shape = getattr(space, "shape", None)
    if shape is not None and np.shape(obs) != tuple(shape):
        raise ConfigError(
            f"{env_id} returned an observation of shape {np.shape(obs)} in episode {episode} at "
            f"step {step}, but its observation space is {space}; nothing of this recording was "
            "written: fix the environment and record again"
        )
    if np.ndim(reward) != 0 or not np.isfinite(float(np.asarray(reward, np.float64))):
        raise ConfigError(
            f"{env_id} returned the reward {reward!r} in episode {episode} at step {step}, not a "
            "finite number; nothing of this recording was written: fix the environment and "
            "record again"
        )


def _check_finite(obs: Any, env_id: str, episode: int, step: int) -> None:
    """Refuse a NaN or infinite observation: a model cannot be fitted to it."""
    if not np.all(np.isfinite(np.asarray(obs, np.float64))):
        raise ConfigError(
            f"{env_id} returned the non-finite observation {np.asarray(obs).tolist()} in episode "
            f"{episode} at step {step}; nothing of this recording was written: fix the "
            "environment (or its parameters) and record again"
        )


@task_hook(method="record_data")
def record_task(task: Any, episodes: int, **options: Any) -> TrajectoryData:
    """Record ``episodes`` episodes of ``task``'s real system, for model learning (``diffcontrol
    record TASK``; ``record_data`` lists the ``options``): Gymnasium episodes for a
    discrete-time task (``record_gym``); a task with data of its own overrides it (the
    trebuchet's throws, the swing-up's states) as ``tasks._hooks`` says, its method named
    ``record_data``."""
    raise ConfigError(f"task {task.name!r} cannot record data (it defines no record_data)")


def record_gym(
    task: Any,
    episodes: int,
    *,
    env_id: str | None = None,
    env_kwargs: dict | None = None,
    controller: str | None = None,
    seed: int = 0,
    max_steps: int | None = None,
    noise_m: float | None = None,
    progress: Callable[[str], None] | None = None,
) -> TrajectoryData:
    """A discrete-time task's ``record_task``: Gymnasium episodes of ``env_id`` (default the task's
    own environment) as the task's real system, with the columns named by the task."""
    env_id = env_id or task.gym_id or own_id(task)
    return _record_env(
        env_id, episodes, task, env_kwargs, controller, seed, max_steps, noise_m, progress
    )


def _record_env(env_id, episodes, task, env_kwargs, controller, seed, max_steps, noise_m, progress):
    if noise_m is not None:
        raise ConfigError(
            f"--noise-m does not apply to recording {env_id} (only to a task's own recording "
            "that measures with noise); drop it"
        )
    # The network alone (observations -> Gymnasium action), whatever the task.
    policy = NumpyPolicy(read_model(controller)) if controller else None
    if progress:
        what = f"controller {controller}" if policy else "random actions"
        progress(f"recording {episodes} episode(s) of {env_id} with {what}")
    return record(
        env_id,
        episodes,
        policy=policy,
        seed=seed,
        env_kwargs=env_kwargs,
        max_steps=max_steps,
        progress=progress,
        source=f"controller {controller} (task {policy.task!r})" if policy else None,
        task=task,
    )


def check_data_file(out: Path, force: bool) -> None:
    """Refuse, before recording anything, an output the recording could not be written to.

    Raises:
        DataFileError: a directory, another extension, an existing file (without ``force``)
            or a directory that cannot be written.
    """
    import os

    if out.is_dir():
        raise DataFileError(f"--out {out} is a directory; give a file name ending in .csv/.npz")
    if out.suffix.lower() not in (".csv", ".npz"):
        raise DataFileError(
            f"--out {out}: unknown file type {out.suffix or '(none)'!r}; use a .csv or .npz file"
        )
    if out.exists() and not force:
        raise DataFileError(
            f"--out {out} already exists; pass --force to overwrite it or choose another --out"
        )
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise DataFileError(
            f"cannot write --out {out}: {parent} is not a writable directory; choose a "
            "writable --out"
        )


def record_data(
    source: str,
    config: RecordConfig,
    out: str | Path | None = None,
    *,
    task: Any = None,
    force: bool = False,
    progress: Callable[[str], None] | None = None,
) -> tuple[Any, Path]:
    """``diffcontrol record``: record ``config.episodes`` episodes and write them to ``out``.

    Args:
        source: a registered task's name (``record_task``: Gymnasium episodes, or the
            task's own recording) or a Gymnasium id (``module:Env-v0`` too; imported because
            the caller named it).
        config: what to record (``RecordConfig``): how many episodes, with which
            controller (a run directory; random actions without), the first reset seed, the
            environment's (or system's) keyword arguments, a cut ``max_steps`` and a noise
            ``noise_m``, as the task's hook takes them.
        out: a ``.csv`` or ``.npz`` file (default: the task's ``data_file_name``, or the id
            with ``/`` as ``-``).
        task: the task whose real system the Gymnasium id ``source`` is (its columns).
        force: overwrite ``out``.
        progress: called with lines.

    Returns:
        The recorded data and the file written.
    """
    env_id: str | None = source
    if task is None and source in tasks.names():
        task, env_id = tasks.make(source), None
    path = Path(
        out or (data_file_name(task, env_id) if task else source.replace("/", "-") + ".csv")
    )
    check_data_file(path, force)
    options = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    episodes = options.pop("episodes")
    if task is not None:
        data = record_task(task, episodes, env_id=env_id, progress=progress, **options)
    else:
        data = _record_env(source, episodes, None, progress=progress, **options)
    try:
        if force:
            write_trajectories(path, data)
        else:  # of two recordings racing for a new file, one wins and the other is told
            io.write_new(path, lambda tmp: write_trajectories(tmp, data))
    except OSError as e:
        raise DataFileError(
            f"cannot write --out {path} ({e.strerror}); choose a writable --out"
        ) from None
    return data, path


def describe(data: TrajectoryData) -> str:
    """One line on recorded data: episodes, steps and columns."""
    kind = "observation" if data.holds == "obs" else "state"
    return (
        f"{data.num_episodes} episode(s), {data.num_steps} steps, "
        f"{len(data.observation_columns)} {kind} and {len(data.action_columns)} action "
        "column(s)"
    )


record_task.register(Task)(record_gym)
