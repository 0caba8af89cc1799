"""The RL baselines of ``diffcontrol compare`` for the MuJoCo tasks: rl-baselines3-zoo's
published hyperparameters (``hyperparams/<algo>.yml``, the entry named beside each; every PPO
entry of these environments normalises observations and rewards), registered with the compare
layer's ``rl_setup`` (``tasks._hooks``).

The zoo's budgets are 1M steps; ``benchmarks/compare.py`` runs the RL methods at a smaller
fixed budget (``--rl-steps``) that fits a CPU. The zoo publishes trained-agent returns
(``benchmark.md``, one run each, 1M steps) for Swimmer only: PPO 281.6, SAC 345.6, TD3 359.1,
TRPO 365.7; quoted in docs/benchmarks.md beside ours.
"""

from __future__ import annotations

from ...compare.baselines import ZOO, Baseline, RLSetup, rl_setup
from .tasks import InvertedDoublePendulum, Reacher, Swimmer


def _sac(source: str, **kwargs) -> Baseline:
    # hyperparams/sac.yml's MuJoCo defaults (the anchor on HalfCheetah-v3): SB3's SAC with
    # 10,000 random steps before learning.
    return Baseline(
        "SAC",
        n_timesteps=1_000_000,
        kwargs=dict(learning_starts=10_000, **kwargs),
        source=f"{ZOO} hyperparams/sac.yml, {source}",
    )


DOUBLE_PENDULUM = RLSetup(
    baselines={
        # hyperparams/ppo.yml, entry InvertedDoublePendulum-v2 ("# Tuned").
        "ppo": Baseline(
            "PPO",
            n_timesteps=1_000_000,
            normalize=True,
            kwargs=dict(
                batch_size=512,
                n_steps=128,
                gamma=0.98,
                learning_rate=0.000155454,
                ent_coef=1.05057e-06,
                clip_range=0.4,
                n_epochs=10,
                gae_lambda=0.8,
                max_grad_norm=0.5,
                vf_coef=0.695929,
            ),
            source=f"{ZOO} hyperparams/ppo.yml, InvertedDoublePendulum-v2",
        ),
        # The zoo has no SAC entry for this environment: its MuJoCo defaults.
        "sac": _sac("the MuJoCo defaults (HalfCheetah-v3); no entry for this environment"),
    },
    thresholds=(9100.0, 9300.0),  # Gymnasium's reward_threshold; issue 41's target
    eval_every=10_000,
)

REACHER = RLSetup(
    baselines={
        # hyperparams/ppo.yml, entry Reacher-v2 ("# Tuned").
        "ppo": Baseline(
            "PPO",
            n_timesteps=1_000_000,
            normalize=True,
            kwargs=dict(
                batch_size=32,
                n_steps=512,
                gamma=0.9,
                learning_rate=0.000104019,
                ent_coef=7.52585e-08,
                clip_range=0.3,
                n_epochs=5,
                gae_lambda=1.0,
                max_grad_norm=0.9,
                vf_coef=0.950368,
            ),
            source=f"{ZOO} hyperparams/ppo.yml, Reacher-v2",
        ),
        "sac": _sac("the MuJoCo defaults (HalfCheetah-v3); no entry for this environment"),
    },
    thresholds=(-3.75,),  # Gymnasium's reward_threshold, issue 41's target
    eval_every=5_000,
)

SWIMMER = RLSetup(
    baselines={
        # hyperparams/ppo.yml, entry Swimmer-v4 ("# tuned"), on the MuJoCo defaults' anchor.
        "ppo": Baseline(
            "PPO",
            n_timesteps=1_000_000,
            n_envs=4,
            normalize=True,
            kwargs=dict(
                gamma=0.9999, n_steps=1024, batch_size=256, learning_rate=6e-4, gae_lambda=0.98
            ),
            source=f"{ZOO} hyperparams/ppo.yml, Swimmer-v4",
        ),
        # hyperparams/sac.yml, entry Swimmer-v3.
        "sac": _sac("Swimmer-v3", gamma=0.9999),
    },
    thresholds=(282.0, 360.0, 366.0),  # above the zoo's PPO; Gymnasium's threshold; above TRPO
    eval_every=10_000,
)

rl_setup.register(InvertedDoublePendulum)(lambda task: DOUBLE_PENDULUM)
rl_setup.register(Reacher)(lambda task: REACHER)
rl_setup.register(Swimmer)(lambda task: SWIMMER)
