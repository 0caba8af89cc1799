"""The RL baselines of ``diffcontrol compare`` for the tasks on Gymnasium's CartPole and
Pendulum: rl-baselines3-zoo's published hyperparameters (``hyperparams/<algo>.yml``, the entry
named beside each), registered with the compare layer's ``rl_setup`` (``tasks._hooks``).
"""

from __future__ import annotations

from ..compare.baselines import ZOO, Baseline, RLSetup, rl_setup
from ..tasks.cartpole import CartPole
from ..tasks.pendulum import Pendulum, PendulumUnclipped

CARTPOLE = RLSetup(
    baselines={
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
            source=f"{ZOO} hyperparams/ppo.yml, CartPole-v1",
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
            source=f"{ZOO} hyperparams/dqn.yml, CartPole-v1",
        ),
    },
    thresholds=(475.0, 500.0),  # Gymnasium's reward_threshold; every episode to its limit
    eval_every=2000,
)

PENDULUM = RLSetup(
    baselines={
        # hyperparams/sac.yml, entry Pendulum-v1: only the learning rate differs from SB3's
        # defaults (buffer 1e6, batch 256, learning_starts 100, tau 0.005, gamma 0.99).
        "sac": Baseline(
            "SAC",
            n_timesteps=20_000,
            kwargs=dict(learning_rate=1e-3),
            source=f"{ZOO} hyperparams/sac.yml, Pendulum-v1",
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
            source=f"{ZOO} hyperparams/td3.yml, Pendulum",
        ),
    },
    thresholds=(-200.0, -150.0),
    eval_every=1000,
)

rl_setup.register(CartPole)(lambda task: CARTPOLE)
rl_setup.register(Pendulum)(lambda task: PENDULUM)
rl_setup.register(PendulumUnclipped)(lambda task: None)  # unclipped torques: no zoo settings
