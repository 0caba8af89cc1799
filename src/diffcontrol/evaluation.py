"""Running a controller in Gymnasium's own environments (the ones users trust)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from .tasks import Task


@dataclasses.dataclass
class EvalResult:
    """Returns of one controller over Gymnasium episodes with seeds ``seed ... seed+n-1``."""

    env_id: str
    seed: int
    returns: np.ndarray
    lengths: np.ndarray

    @property
    def mean(self) -> float:
        return float(np.mean(self.returns))

    @property
    def std(self) -> float:
        return float(np.std(self.returns))

    def to_json(self) -> dict[str, Any]:
        return {
            "env_id": self.env_id,
            "episodes": int(self.returns.size),
            "seeds": [self.seed, self.seed + int(self.returns.size) - 1],
            "mean_return": self.mean,
            "std_return": self.std,
            "min_return": float(np.min(self.returns)),
            "max_return": float(np.max(self.returns)),
            "mean_length": float(np.mean(self.lengths)),
            "returns": self.returns.tolist(),
        }


@dataclasses.dataclass
class Recording:
    """One episode recorded in Gymnasium: the true states (not just observations)."""

    env_id: str
    dt: float
    states: np.ndarray  # [T+1, state]
    actions: np.ndarray  # [T, act] the controller's continuous action
    rewards: np.ndarray  # [T]

    @property
    def total_return(self) -> float:
        return float(np.sum(self.rewards))


def evaluate(
    policy: Callable[[np.ndarray], Any], task: Task, episodes: int = 100, seed: int = 0
) -> EvalResult:
    """Run ``policy`` (observation -> Gymnasium action) in ``task``'s Gymnasium environment.

    Episode ``i`` is reset with ``seed + i``; each runs until Gymnasium terminates or
    truncates it. This is the standard protocol, so the mean return compares with any
    other method evaluated on the same seeds.
    """
    if episodes <= 0:
        raise ValueError(f"episodes must be positive, got {episodes}")
    env = task.make_gym_env()
    returns, lengths = [], []
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            total, n, done = 0.0, 0, False
            while not done:
                obs, reward, terminated, truncated, _ = env.step(policy(obs))
                total += float(reward)
                n += 1
                done = terminated or truncated
            returns.append(total)
            lengths.append(n)
    finally:
        env.close()
    return EvalResult(task.gym_label, seed, np.asarray(returns), np.asarray(lengths))


def record_episode(policy: Any, task: Task, seed: int = 0) -> Recording:
    """Record one Gymnasium episode of ``policy`` (a ``NumpyPolicy``) with the true states."""
    env = task.make_gym_env()
    try:
        obs, _ = env.reset(seed=seed)
        states = [np.array(env.unwrapped.state, dtype=np.float64)]
        actions, rewards = [], []
        done = False
        while not done:
            actions.append(np.asarray(policy.action(obs), np.float64).reshape(-1))
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            states.append(np.array(env.unwrapped.state, dtype=np.float64))
            rewards.append(float(reward))
            done = terminated or truncated
        dt = float(getattr(env.unwrapped, "dt", getattr(env.unwrapped, "tau", 0.02)))
    finally:
        env.close()
    return Recording(
        env_id=task.gym_label,
        dt=dt,
        states=np.stack(states),
        actions=np.stack(actions),
        rewards=np.asarray(rewards),
    )
