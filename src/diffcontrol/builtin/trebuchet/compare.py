"""The trebuchet's RL baselines for ``diffcontrol compare`` (``compare.rl_setup``)."""

from __future__ import annotations

from ...compare.baselines import Baseline, RLSetup

RL = RLSetup(
    baselines={
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
    # Minus the mean |miss| in metres over random situations, out-of-reach targets included
    # (about 7 % of them, whose misses no aim can avoid).
    thresholds=(-2.0, -1.0),
    eval_every=1000,
)
