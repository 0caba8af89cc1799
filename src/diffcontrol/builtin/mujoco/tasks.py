"""Gymnasium's MuJoCo environments, step for step: the same model file, frame skip,
observation, reward and termination as ``gymnasium.make(<id>)`` (v5, default arguments).

The physics differs from Gymnasium's only in the constraint solver's iterations (1 here, for
reverse mode; MuJoCo's default 100 there), which changes nothing while no joint limit is
engaged (``systems.mjx``), and in float32 (``tests/test_mujoco.py`` states the tolerances).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ...config import TrainConfig
from ...tasks import Stroke
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

    def state_from_observation(self, observation):
        # Exact to rounding while the speeds and the slider's force are inside the
        # observation's clip (+-10).
        hinges = jnp.arctan2(observation[1:3], observation[3:5])
        return jnp.concatenate([observation[:1], hinges, observation[5:9]])

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
        # 20-step windows (1 s) of 16 simulations: long enough to see a fall coming, short
        # enough that the unstable poles' gradients stay informative; the best of the
        # evaluation points is kept (keep_best), as the return can dip between them.
        return TrainConfig(
            updates=1000,
            batch=16,
            window=20,
            horizon=1000,
            learning_rate=3e-3,
            hidden=(64, 64),
            eval_every=100,
            eval_episodes=32,
            target_return=float("nan"),
        )


class Reacher(MujocoTask):
    """Bring a two-link arm's fingertip to a target (``Reacher-v5``), torques ``|u| <= 1``.

    Reward per step: minus the fingertip's distance to the target and minus ``|u|^2``; 50
    steps, no termination. The target's position is the model's last two ``qpos`` (slide
    joints that nothing drives).

    Training losses (per step): ``cost``, minus the reward.
    """

    name = "reacher"
    summary = "Reacher-v5 by BPTT through MJX on Gymnasium's own model file"
    gym_id = "Reacher-v5"
    reward_threshold = -3.75
    model_file = "reacher.xml"
    frame_skip = 2
    extras_size = 2
    episode_length = 50
    observation_size = 10
    action_size = 2
    action_head = "tanh"
    action_low = (-1.0, -1.0)
    action_high = (1.0, 1.0)

    def initial_qpos_qvel(self, key):
        # Gymnasium's reset_model: arm angles qpos0 + U(-0.1, 0.1), a target uniform in the
        # disc of radius 0.2 (drawn there by rejection; here by its radius and angle, the same
        # distribution), arm speeds U(-0.005, 0.005), the target at rest.
        k_pos, k_r, k_a, k_vel = jax.random.split(key, 4)
        arm = self.system.init_qpos[:2] + jax.random.uniform(k_pos, (2,), minval=-0.1, maxval=0.1)
        radius = 0.2 * jnp.sqrt(jax.random.uniform(k_r))
        angle = jax.random.uniform(k_a, minval=-jnp.pi, maxval=jnp.pi)
        goal = radius * jnp.stack([jnp.cos(angle), jnp.sin(angle)])
        qvel = jax.random.uniform(k_vel, (2,), minval=-0.005, maxval=0.005)
        return jnp.concatenate([arm, goal]), jnp.concatenate([qvel, jnp.zeros(2)])

    def to_target(self, data):
        """Fingertip minus target (3 numbers), from the bodies' frames in ``data``."""
        return data.xpos[self.body_id("fingertip")] - data.xpos[self.body_id("target")]

    def extras(self, data):
        return self.to_target(data)[:2]

    def observe(self, state):
        qpos, qvel = state[:4], state[4:8]
        return jnp.concatenate(
            [jnp.cos(qpos[:2]), jnp.sin(qpos[:2]), qpos[2:], qvel[:2], state[8:10]]
        )

    def state_from_observation(self, observation):
        # The target never moves (nothing drives its slide joints): its speeds are zero.
        arm = jnp.arctan2(observation[2:4], observation[:2])
        qvel = jnp.concatenate([observation[6:8], jnp.zeros_like(observation[:2])])
        return jnp.concatenate([arm, observation[4:6], qvel, observation[8:10]])

    def reward(self, state, action, next_state, data):
        reward = -jnp.linalg.norm(self.to_target(data)) - jnp.sum(jnp.square(action))
        return reward, jnp.asarray(False)

    def default_config(self):
        # Whole 50-step episodes of 32 simulations per update; 2,000 updates (1,000 end at
        # -4.07 in Gymnasium, 2,000 at -3.75: docs/benchmarks.md).
        return TrainConfig(
            updates=2000,
            batch=32,
            window=50,
            horizon=50,
            learning_rate=1e-2,
            hidden=(64, 64),
            eval_every=100,
        )


SWIMMER_CTRL_COST = 1e-4
"""Swimmer-v5's ``ctrl_cost_weight``."""


class Swimmer(MujocoTask):
    """Swim forward in a viscous fluid with three links and two joint torques (``Swimmer-v5``).

    Reward per step: the front tip's forward speed ``(x' - x) / dt`` (``dt = 0.04`` s) minus
    ``1e-4 |u|^2``; 1000 steps, no termination. The observation leaves out the position in
    the plane (Gymnasium's default).

    Training losses (per step): ``cost``, minus the reward.
    """

    name = "swimmer"
    summary = "Swimmer-v5 by BPTT through MJX on Gymnasium's own model file"
    gym_id = "Swimmer-v5"
    reward_threshold = 360.0
    model_file = "swimmer.xml"
    frame_skip = 4
    reset_velocity = "uniform"  # Gymnasium's: U(-0.1, 0.1) positions and speeds
    episode_length = 1000
    observation_size = 8
    action_size = 2
    action_head = "tanh"
    action_low = (-1.0, -1.0)
    action_high = (1.0, 1.0)
    # The speeds to about unit size for the controller's first layer: a stroke turns the
    # joints at up to 4-5 rad/s and the body at about 2.
    obs_scale = (1.0, 1.0, 1.0, 1.0, 1.0, 0.5, 0.25, 0.25)

    def observe(self, state):
        return state[2:]

    def state_from_observation(self, observation):
        # The position in the plane, which the observation leaves out, at the origin: the
        # fluid is the same everywhere, so the steps and the rewards do not depend on it.
        return jnp.concatenate([jnp.zeros_like(observation[:2]), observation])

    def reward(self, state, action, next_state, data):
        speed = (next_state[0] - state[0]) / self.dt
        return speed - SWIMMER_CTRL_COST * jnp.sum(jnp.square(action)), jnp.asarray(False)

    def stroke(self):
        # The best clipped sinusoid of benchmarks/swimmer_gaits.py's search (286 in Gymnasium
        # open loop): from random weights BPTT finds a held pose or a slow stroke instead.
        return Stroke(period=57.08, amplitude=(2.707, 2.439), phase=(-1.350, -1.435))

    def default_config(self):
        # From the stroke, at a rate that refines it (3e-3 unlearns it within 200 updates).
        return TrainConfig(
            updates=200,
            batch=16,
            window=50,
            horizon=1000,
            learning_rate=3e-4,
            hidden=(64, 64),
            eval_every=25,
        )
