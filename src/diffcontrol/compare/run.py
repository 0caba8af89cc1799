"""Train diffcontrol and the RL baselines on one task and evaluate them all the same way.

Protocol (``run_method``), identical for every method:

- The same training seed for diffcontrol (``TrainConfig.seed``) and for Stable-Baselines3
  (the model's and its environments' seed).
- At regular points during training (diffcontrol: its own evaluation points, every
  ``eval_every`` updates; RL: every ``eval_every`` environment steps) the current controller
  runs ``eval_episodes`` deterministic episodes in the same environment on the same reset
  seeds ``eval_seed ... eval_seed + eval_episodes - 1``: Gymnasium's own ``Pendulum-v1`` /
  ``CartPole-v1`` where the task has one, else ``diffcontrol/<Name>-v0``.
- The controller each method returns (diffcontrol: the best of its in-simulator evaluation
  points, chosen on its own simulated starts; RL: the last) gets ``final_episodes`` episodes
  on seeds ``eval_seed ...``.
- Training seconds exclude every evaluation above (reported apart as ``eval_seconds``) and
  include everything else: JAX compilation and diffcontrol's own in-simulator evaluations;
  building the SB3 model and its environments.
- Environment steps count every simulated step used for training (diffcontrol: ``updates x
  window x batch``; RL: ``model.num_timesteps``). ``episodes`` is that divided by the task's
  standard episode length (the unit of diffcontrol's ``simulated_episodes``);
  ``episodes_finished`` counts the training episodes that actually ended.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import gymnasium
import numpy as np

from .. import _gym, envs, policies
from ..errors import ConfigError
from ..tasks import Task
from ..training import resolve_config, train
from .baselines import build_model, rl_setup


def make_eval_env(task: Task) -> gymnasium.Env:
    """The environment every method is evaluated (and RL trained) in: Gymnasium's own where
    the task has one (``Pendulum-v1``, ``CartPole-v1``), else ``diffcontrol/<Name>-v0``."""
    if task.gym_id is not None:
        return _gym.make_gym_env(task)
    return gymnasium.make(envs.env_id(task))


def evaluate_batch(
    act: Callable[[np.ndarray], Any], task: Task, episodes: int, seed: int
) -> np.ndarray:
    """Returns of ``episodes`` episodes, episode ``i`` reset with ``seed + i``, run side by side.

    The same protocol as ``diffcontrol.evaluate`` (each episode runs until its environment
    terminates or truncates it), with one call of ``act`` per step for all running episodes.

    Args:
        act: ``[n, obs] -> n`` Gymnasium actions (deterministic).
        task: the task; episodes run in ``make_eval_env(task)``.
        episodes: how many (> 0).
        seed: the reset seed of the first episode.

    Returns:
        The ``[episodes]`` undiscounted returns.
    """
    if episodes <= 0:
        raise ConfigError(f"episodes must be positive, got {episodes}")
    pool = [make_eval_env(task) for _ in range(episodes)]
    obs = [env.reset(seed=seed + i)[0] for i, env in enumerate(pool)]
    returns = np.zeros(episodes)
    running = list(range(episodes))
    try:
        while running:
            actions = act(np.stack([obs[i] for i in running]))
            still = []
            for i, a in zip(running, actions):
                obs[i], reward, terminated, truncated, _ = pool[i].step(a)
                returns[i] += float(reward)
                if not (terminated or truncated):
                    still.append(i)
            running = still
    finally:
        for env in pool:
            env.close()
    return returns


def numpy_policy_act(policy: Any) -> Callable[[np.ndarray], list]:
    """Batch ``act`` of a ``NumpyPolicy`` with the Gymnasium actions ``policy(obs)`` gives."""

    def act(obs: np.ndarray) -> list:
        return [policy(o) for o in obs]

    return act


def sb3_act(model: Any) -> Callable[[np.ndarray], Any]:
    """Batch ``act`` of a Stable-Baselines3 model (deterministic actions), on observations
    normalised as in its training where that normalises them (``VecNormalize``'s statistics
    of that moment, not updated by the evaluation)."""
    normalize = model.get_vec_normalize_env()

    def act(obs: np.ndarray) -> Any:
        if normalize is not None:
            obs = normalize.normalize_obs(obs)
        actions, _ = model.predict(obs, deterministic=True)
        return actions

    return act


def _point(steps: int, finished: int, seconds: float, returns: np.ndarray, task: Task) -> dict:
    return {
        "env_steps": int(steps),
        "episodes": steps / task.episode_length,
        "episodes_finished": int(finished),
        "train_seconds": float(seconds),
        "mean_return": float(np.mean(returns)),
        "std_return": float(np.std(returns)),
    }


def first_reached(curve: list[dict], threshold: float) -> dict | None:
    """The first evaluation point whose mean return is at least ``threshold`` (or ``None``)."""
    for point in curve:
        if point["mean_return"] >= threshold:
            return point
    return None


def run_diffcontrol(
    task: Task,
    seed: int,
    *,
    updates: int | None,
    eval_episodes: int,
    final_episodes: int,
    eval_seed: int,
    say: Callable[[str], None],
) -> dict:
    """Train diffcontrol's default configuration with ``seed``; evaluate as described above."""
    config = resolve_config(task, seed=seed, updates=updates)
    curve: list[dict] = []
    eval_seconds = 0.0

    def policy_of(controller) -> Any:
        return policies.NumpyPolicy(policies.controller_to_dict(controller, task, {}))

    def on_point(point: dict, controller) -> None:
        nonlocal eval_seconds
        t0 = time.perf_counter()
        returns = evaluate_batch(
            numpy_policy_act(policy_of(controller)), task, eval_episodes, eval_seed
        )
        eval_seconds += time.perf_counter() - t0
        p = _point(
            point["simulated_steps"],
            point["train_episodes_finished"],
            point["seconds"],
            returns,
            task,
        )
        curve.append(p)
        say(_line("diffcontrol", seed, p))

    result = train(task, config, on_point=on_point)
    t0 = time.perf_counter()
    final = evaluate_batch(
        numpy_policy_act(policy_of(result.controller)), task, final_episodes, eval_seed
    )
    eval_seconds += time.perf_counter() - t0
    m = result.metrics
    return {
        "method": "diffcontrol",
        "algo": "BPTT through the simulator (diffcontrol train defaults)",
        "source": f"diffcontrol {task.name} default_config()",
        "seed": seed,
        "config": config.to_json(),
        "env_steps": m["simulated_steps"],
        "episodes": m["simulated_episodes"],
        "train_seconds": m["train_seconds"],
        "compile_seconds": m["compile_seconds"],
        "eval_seconds": eval_seconds,
        "returned_update": m["returned_update"],
        "curve": curve,
        "final": _final(final),
    }


def run_rl(
    task: Task,
    method: str,
    seed: int,
    *,
    steps: int | None,
    eval_every: int,
    eval_episodes: int,
    final_episodes: int,
    eval_seed: int,
    torch_threads: int | None,
    say: Callable[[str], None],
) -> dict:
    """Train the RL baseline ``method`` with ``seed``; evaluate every ``eval_every`` steps."""
    from stable_baselines3.common.callbacks import BaseCallback

    baseline = rl_setup(task).baselines[method]
    budget = int(steps or baseline.n_timesteps)
    t_start = time.perf_counter()
    model = build_model(baseline, lambda: make_eval_env(task), seed, torch_threads)
    curve: list[dict] = []
    state = {"eval_seconds": 0.0, "finished": 0, "next": eval_every}

    def evaluate_now() -> None:
        t0 = time.perf_counter()
        seconds = t0 - t_start - state["eval_seconds"]
        returns = evaluate_batch(sb3_act(model), task, eval_episodes, eval_seed)
        state["eval_seconds"] += time.perf_counter() - t0
        p = _point(model.num_timesteps, state["finished"], seconds, returns, task)
        curve.append(p)
        say(_line(method, seed, p))

    class Every(BaseCallback):
        def _on_step(self) -> bool:
            state["finished"] += int(np.sum(self.locals.get("dones", 0)))
            if self.num_timesteps >= state["next"]:
                while state["next"] <= self.num_timesteps:
                    state["next"] += eval_every
                evaluate_now()
            return True

    model.learn(total_timesteps=budget, callback=Every())
    if not curve or curve[-1]["env_steps"] != model.num_timesteps:
        evaluate_now()
    train_seconds = curve[-1]["train_seconds"]
    t0 = time.perf_counter()
    final = evaluate_batch(sb3_act(model), task, final_episodes, eval_seed)
    state["eval_seconds"] += time.perf_counter() - t0
    model.get_env().close()
    return {
        "method": method,
        "algo": baseline.algo,
        "source": baseline.source,
        "seed": seed,
        "config": {
            "n_timesteps": budget,
            "n_envs": baseline.n_envs,
            **({"normalize": True} if baseline.normalize else {}),
            **{k: _jsonable(v) for k, v in baseline.kwargs.items()},
        },
        "env_steps": int(model.num_timesteps),
        "episodes": model.num_timesteps / task.episode_length,
        "train_seconds": train_seconds,
        "eval_seconds": state["eval_seconds"],
        "curve": curve,
        "final": _final(final),
    }


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [_jsonable(v) for v in value]
    return value


def _final(returns: np.ndarray) -> dict:
    return {
        "episodes": int(returns.size),
        "mean_return": float(np.mean(returns)),
        "std_return": float(np.std(returns)),
        "returns": returns.tolist(),
    }


def _line(method: str, seed: int, p: dict) -> str:
    ret = p["mean_return"]
    ret_s = f"{ret:9.2f}" if math.isfinite(ret) else "      nan"
    return (
        f"  {method:<11} seed {seed:<3} steps {p['env_steps']:>9,}  episodes "
        f"{p['episodes']:>9.1f}  return {ret_s} ± {p['std_return']:<7.1f} "
        f"train {p['train_seconds']:7.1f} s"
    )
