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


# ---------------------------------------------------------------------------------------------
# Aiming tasks (the trebuchet): miss statistics over random situations in the simulator.


@dataclasses.dataclass
class AimResult:
    """Misses of an aiming controller over random targets and winds (seeded NumPy draws).

    Only reachable targets count in the statistics; ``unreachable`` says how many were not.
    """

    task: str
    seed: int
    targets: np.ndarray
    winds: np.ndarray
    angles: np.ndarray
    weights: np.ndarray
    distances: np.ndarray
    reachable: np.ndarray

    @property
    def misses(self) -> np.ndarray:
        return self.distances - self.targets

    @property
    def stats(self) -> dict[str, Any]:
        from .tasks.trebuchet import miss_statistics

        return miss_statistics(self.misses, self.reachable)

    def to_json(self) -> dict[str, Any]:
        return {"task": self.task, "seed": self.seed, **self.stats}

    def summary(self) -> str:
        s = self.stats
        if not s["reachable"]:
            return f"none of the {s['targets']} targets was reachable"
        return (
            f"|miss| over {s['reachable']} reachable targets: mean {s['mean_miss_m']:.3f} m, "
            f"median {s['median_miss_m']:.3f} m, 95th percentile {s['p95_miss_m']:.3f} m, "
            f"worst {s['worst_miss_m']:.3f} m ({s['unreachable']} of {s['targets']} unreachable)"
        )


def evaluate_aiming(policy: Any, task: Task, targets: int = 1000, seed: int = 0) -> AimResult:
    """Aim ``policy`` (a ``model.json`` policy) at ``targets`` random situations.

    Targets ~ U(20, 100) m and winds ~ N(0, 5^2) m/s (clipped to +-20 m/s) are drawn with
    ``numpy.random.default_rng(seed)``, so every controller meets the same situations. Each
    throw is simulated with ``diffcontrol.systems.trebuchet.shoot``; a target counts as
    reachable when it lies between the shortest and longest throws the heads' bounds allow
    in its wind (``reachable_range``).
    """
    import jax

    from .systems import trebuchet as tb
    from .tasks import trebuchet as aim

    if targets <= 0:
        raise ValueError(f"targets must be positive, got {targets}")
    rng = np.random.default_rng(seed)
    target = rng.uniform(*aim.TARGET_RANGE_M, size=targets)
    wind = np.clip(
        aim.WIND_STD_MPS * rng.standard_normal(targets), -aim.WIND_LIMIT_MPS, aim.WIND_LIMIT_MPS
    )
    actions = policy.action(np.stack([target, wind], axis=-1))
    angle, weight = actions[:, 0], actions[:, 1]
    distance = np.asarray(jax.jit(tb.shoot)(wind, angle, weight), np.float64)
    shortest, longest = (np.asarray(x, np.float64) for x in aim.reachable_range(wind))
    reachable = (target >= shortest) & (target <= longest)
    return AimResult(task.name, seed, target, wind, angle, weight, distance, reachable)
