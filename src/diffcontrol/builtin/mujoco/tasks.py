"""Gymnasium's MuJoCo environments, step for step: the same model file, frame skip,
observation, reward and termination as ``gymnasium.make(<id>)`` (v5, default arguments).

The physics differs from Gymnasium's only in the constraint solver's iterations (1 here, for
reverse mode; MuJoCo's default 100 there), which changes nothing while no joint limit is
engaged (``systems.mjx``), and in float32 (``tests/test_mujoco.py`` states the tolerances).
"""

from __future__ import annotations

import jax.numpy as jnp

from ...config import TrainConfig
from ...tasks.mujoco import MujocoTask

HEALTHY_REWARD = 10.0
"""The double pendulum's reward per step while its tip is above 1 m (``healthy_reward``)."""


class InvertedDoublePendulum(MujocoTask):
    """Balance two poles on a cart (``InvertedDoublePendulum-v5``), force ``|u| <= 1`` x 500 N.

    Reward per step: 10 while the second pole's tip is above ``y = 1`` m, minus
    ``0.01 x^2 + (y - 2)^2`` of the tip and ``1e-3 w1^2 + 5e-3 w2^2`` of the hinges' speeds;
    the episode ends when the tip is at or below 1 m. The most a step can earn is about 9.36
    (the tip's top is 1.2 m), so a 1000-step episode earns at most about 9,360.

    Training losses (per step):

    - ``cost``: the penalties, ``10 - reward`` while upright (the bonus has no gradient).
    """

    name = "inverted-double-pendulum"
    summary = "InvertedDoublePendulum-v5 by BPTT through MJX on Gymnasium's own model file"
    gym_id = "InvertedDoublePendulum-v5"
    model_file = "inverted_double_pendulum.xml"
    frame_skip = 5
    extras_size = 1
    episode_length = 1000
    observation_size = 9
    action_size = 1
    action_head = "tanh"
    action_low = (-1.0,)
    action_high = (1.0,)
    obs_scale = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.1, 0.1, 0.1)
    reward_threshold = 9100.0
    losses = ("cost",)
    state_labels = (
        "cart x (m)",
        "hinge 1 (rad)",
        "hinge 2 (rad)",
        "cart speed (m/s)",
        "hinge 1 speed (rad/s)",
        "hinge 2 speed (rad/s)",
        "slider force (N)",
    )
    action_labels = ("force / 500 N",)

    def extras(self, data):
        # Gymnasium observes the slider's constraint force (its limit; 0 while off it).
        return data.qfrc_constraint[:1]

    def observe(self, state):
        qpos, qvel = state[:3], state[3:6]
        return jnp.concatenate(
            [
                qpos[:1],
                jnp.sin(qpos[1:]),
                jnp.cos(qpos[1:]),
                jnp.clip(qvel, -10, 10),
                jnp.clip(state[6:7], -10, 10),
            ]
        )

    def penalties(self, next_state, data):
        """``(terminated, dist_penalty + vel_penalty)`` after a step."""
        x, y = data.site_xpos[0, 0], data.site_xpos[0, 2]
        w1, w2 = next_state[4], next_state[5]
        penalty = 0.01 * x**2 + (y - 2) ** 2 + 1e-3 * w1**2 + 5e-3 * w2**2
        return y <= 1, penalty

    def reward(self, state, action, next_state, data):
        terminated, penalty = self.penalties(next_state, data)
        return jnp.where(terminated, 0.0, HEALTHY_REWARD) - penalty, terminated

    def step_loss(self, name):
        if name == "cost":
            return lambda params, state, action, next_state, reward: HEALTHY_REWARD - reward
        raise KeyError(name)

    def default_config(self):
        return TrainConfig(
            updates=300,
            batch=16,
            window=50,
            horizon=1000,
            learning_rate=3e-3,
            hidden=(64, 64),
            eval_every=50,
            eval_episodes=16,
            target_return=float("nan"),
        )
