"""Reinforcement-learning baselines from Stable-Baselines3, with rl-baselines3-zoo's settings.

The hyperparameters below are the ones published by DLR-RM/rl-baselines3-zoo for each
environment, copied value by value from its ``hyperparams/<algo>.yml`` (the file and entry are
named next to each). Settings the zoo leaves out are Stable-Baselines3's defaults, as in the
zoo. ``lin_X`` in the zoo is a learning rate (or clip range) that decays linearly from ``X``
to 0 over the budget; ``noise_std`` is the standard deviation of Gaussian action noise in
Stable-Baselines3's normalised ``[-1, 1]`` action space.

Stable-Baselines3 and PyTorch are imported only when a baseline is built, so the rest of
diffcontrol works without them; ``require_rl()`` raises a ``DiffcontrolError`` naming the
install command when they are missing. Models are never saved or loaded here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from ..errors import DiffcontrolError

INSTALL_HINT = "install the rl extra: pip install 'diffcontrol[rl]'"


@dataclasses.dataclass(frozen=True)
class Baseline:
    """One RL algorithm with its published settings for one task.

    Attributes:
        algo: the Stable-Baselines3 class name (``"PPO"``, ``"DQN"``, ``"SAC"``, ``"TD3"``).
        n_timesteps: the zoo's training budget in environment steps.
        n_envs: environments stepped side by side (PPO's ``n_envs``).
        kwargs: constructor arguments; ``"lin_X"`` strings become linear schedules,
            ``noise_std`` becomes ``NormalActionNoise``.
        source: where the values were published.
    """

    algo: str
    n_timesteps: int
    n_envs: int = 1
    kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    source: str = ""


_ZOO = "DLR-RM/rl-baselines3-zoo"

BASELINES: dict[str, dict[str, Baseline]] = {
    "cartpole": {
        # hyperparams/ppo.yml, entry CartPole-v1 ("# Tuned").
        "ppo": Baseline(
            "PPO",
            n_timesteps=100_000,
            n_envs=8,
            kwargs=dict(
                n_steps=32,
                batch_size=256,
                gae_lambda=0.8,
                gamma=0.98,
                n_epochs=20,
                ent_coef=0.0,
                learning_rate="lin_0.001",
                clip_range="lin_0.2",
            ),
            source=f"{_ZOO} hyperparams/ppo.yml, CartPole-v1",
        ),
        # hyperparams/dqn.yml, entry CartPole-v1 ("# Almost Tuned").
        "dqn": Baseline(
            "DQN",
            n_timesteps=50_000,
            kwargs=dict(
                learning_rate=2.3e-3,
                batch_size=64,
                buffer_size=100_000,
                learning_starts=1000,
                gamma=0.99,
                target_update_interval=10,
                train_freq=256,
                gradient_steps=128,
                exploration_fraction=0.16,
                exploration_final_eps=0.04,
                policy_kwargs=dict(net_arch=[256, 256]),
            ),
            source=f"{_ZOO} hyperparams/dqn.yml, CartPole-v1",
        ),
    },
    "pendulum": {
        # hyperparams/sac.yml, entry Pendulum-v1: only the learning rate differs from SB3's
        # defaults (buffer 1e6, batch 256, learning_starts 100, tau 0.005, gamma 0.99).
        "sac": Baseline(
            "SAC",
            n_timesteps=20_000,
            kwargs=dict(learning_rate=1e-3),
            source=f"{_ZOO} hyperparams/sac.yml, Pendulum-v1",
        ),
        # hyperparams/td3.yml, entry Pendulum (the same values are those of the zoo's
        # published sb3/td3-Pendulum-v1 agent).
        "td3": Baseline(
            "TD3",
            n_timesteps=20_000,
            kwargs=dict(
                gamma=0.98,
                buffer_size=200_000,
                learning_starts=10_000,
                noise_std=0.1,
                gradient_steps=-1,
                train_freq=(1, "episode"),
                learning_rate=1e-3,
                policy_kwargs=dict(net_arch=[400, 300]),
            ),
            source=f"{_ZOO} hyperparams/td3.yml, Pendulum",
        ),
    },
    "trebuchet": {
        # No published settings exist for this one-step task. Our choice: the zoo's Pendulum
        # settings of each algorithm (a 2-D box action, dense reward), with 1,000 random
        # warm-up throws, and one gradient step per throw (an episode is one throw). The
        # discount does not matter: every episode ends after its only step.
        "sac": Baseline(
            "SAC",
            n_timesteps=20_000,
            kwargs=dict(learning_rate=1e-3, learning_starts=1000),
            source="diffcontrol's choice: SAC as in the zoo's Pendulum-v1, 1,000 warm-up steps",
        ),
        "td3": Baseline(
            "TD3",
            n_timesteps=20_000,
            kwargs=dict(
                buffer_size=200_000,
                learning_starts=1000,
                noise_std=0.1,
                train_freq=1,
                gradient_steps=1,
                learning_rate=1e-3,
                policy_kwargs=dict(net_arch=[400, 300]),
            ),
            source="diffcontrol's choice: TD3 as in the zoo's Pendulum, 1,000 warm-up steps, "
            "one gradient step per throw",
        ),
    },
}
"""``BASELINES[task][method]``: the RL baselines that ``diffcontrol compare`` runs."""


def require_rl() -> None:
    """Raise a ``DiffcontrolError`` with the install command if SB3 or PyTorch is missing."""
    try:
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError as e:
        raise DiffcontrolError(
            f"the RL baselines need Stable-Baselines3 and PyTorch ({e}); {INSTALL_HINT}"
        ) from None


def _linear(initial: float) -> Callable[[float], float]:
    """The zoo's ``lin_X``: ``X`` times the remaining fraction of the budget (1 -> 0)."""

    def schedule(progress_remaining: float) -> float:
        return progress_remaining * initial

    return schedule


def build_model(
    baseline: Baseline, make_env: Callable[[], Any], seed: int, torch_threads: int | None = 1
) -> Any:
    """Construct the Stable-Baselines3 model of ``baseline`` on fresh environments.

    Args:
        baseline: the algorithm and its settings.
        make_env: returns one new Gymnasium environment (called ``n_envs`` times).
        seed: seeds the model, its environments and PyTorch.
        torch_threads: PyTorch's intra-op threads (``None`` leaves PyTorch's default).

    Returns:
        The untrained model (``model.learn(...)`` trains it).

    Raises:
        DiffcontrolError: Stable-Baselines3 is not installed.
    """
    require_rl()
    import numpy as np
    import stable_baselines3 as sb3
    import torch
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.noise import NormalActionNoise

    if torch_threads:
        torch.set_num_threads(int(torch_threads))
    env = make_vec_env(make_env, n_envs=baseline.n_envs, seed=seed)
    kwargs = dict(baseline.kwargs)
    for name in ("learning_rate", "clip_range"):
        value = kwargs.get(name)
        if isinstance(value, str) and value.startswith("lin_"):
            kwargs[name] = _linear(float(value[4:]))
    if "noise_std" in kwargs:
        n = env.action_space.shape[-1]
        std = kwargs.pop("noise_std")
        kwargs["action_noise"] = NormalActionNoise(mean=np.zeros(n), sigma=std * np.ones(n))
    cls = getattr(sb3, baseline.algo)
    return cls("MlpPolicy", env, seed=seed, device="cpu", verbose=0, **kwargs)
