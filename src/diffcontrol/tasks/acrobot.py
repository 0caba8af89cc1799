"""Acrobot swing-up: Gymnasium's ``Acrobot-v1`` with a three-way straight-through choice."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..config import TrainConfig
from ..settings import PlanConfig
from ..systems import acrobot as ac
from ._base import StepLoss, Task


class Acrobot(Task):
    """Swing the acrobot's tip above the line at height 1 in as few steps as possible.

    The controller's ``argmax`` head picks one of Gymnasium's three actions as a one-hot
    vector ``c``; the torque is ``c . (-1, 0, +1)`` N m, so the straight-through softmax
    gradient of the head reaches the dynamics.

    Gymnasium's reward is -1 per step until the goal: flat, so its gradient through the
    simulator is zero everywhere (the goal test has no derivative) and BPTT on it learns
    nothing. The training losses are shaped instead (per step; ``tau`` the step's torque,
    ``theta2_dot`` the pre-step speed of the driven joint, ``h`` the post-step tip height in
    link lengths):

    - ``pump`` (default): ``-tau theta2_dot + w sigmoid((h_goal - h) / s)`` with ``w = 2``,
      ``s = 0.5``. The first term is minus the power the motor puts into the links (the
      mechanical energy changes at the rate ``tau theta2_dot``), so its sum over a window is
      about minus the energy gained: it teaches the swing (energy pumping, Spong 1995). The
      second is a soft "not at the goal yet" indicator, about 1 well below the line and 0 above
      it, whose sum is a soft time-to-goal: it teaches when to cross the line, which pure
      pumping does not. Its slope is non-zero only within a few ``s`` of the line, where the
      pumping has brought the tip.
    - ``power``: the pumping term alone (learns the pump ``tau = sign(theta2_dot)``).
    - ``reach``: ``pump`` with the goal term weighted ``w = 30``, the planner's default
      (``diffcontrol plan acrobot``): with ``w = 2`` the power term, up to ``|tau| max_vel_2
      = 9 pi`` a step, outweighs the goal and a planner looking 20 steps ahead keeps pumping
      energy in past the line; weighted 30 it crosses (docs/benchmarks.md, "Acrobot").

    Not the tip height or the energy themselves: near the hanging rest state both are
    quadratic in the swing's amplitude, so their gradient vanishes there and training on them
    settles on standing still. Training ranks evaluation points by Gymnasium's return in the
    simulator (``keep_best``), so the loss only has to lead there.

    The power term pays for swinging on rather than finishing, which the goal term only
    offsets within ``s`` of the line: the longest episodes hold one torque while the first
    link spins at its speed limit, which turns the motor's work into the clip's losses.
    Figures, and the losses compared with these, are in docs/benchmarks.md, "Acrobot".
    """

    positive_params = (
        "link_length_1", "link_length_2", "link_mass_1", "link_mass_2", "link_com_pos_1",
        "link_com_pos_2", "link_moi", "dt", "max_vel_1", "max_vel_2",
    )  # fmt: skip
    name = "acrobot"
    # Not the older emitters: they change the chunk's bits and slow the evaluation.
    fast_compile = {
        "chunk": ("xla_backend_optimization_level",),
        "evaluate": ("xla_backend_optimization_level",),
    }
    summary = (
        "Acrobot-v1 swing-up: a 3-way straight-through choice of torque (exact Gymnasium dynamics)"
    )
    gym_id = "Acrobot-v1"
    episode_length = ac.EPISODE_LENGTH
    observation_size = 6
    action_size = len(ac.TORQUES)
    action_head = "argmax"
    obs_scale = (1.0, 1.0, 1.0, 1.0, 0.5, 0.25)
    reward_threshold = -100.0
    losses = ("pump", "power", "reach")
    state_labels = (
        "link 1 angle θ1 (rad, 0 = down)",
        "link 2 angle θ2 (rad, relative to link 1)",
        "link 1 speed θ̇1 (rad/s)",
        "link 2 speed θ̇2 (rad/s)",
    )
    # One label per component of the one-hot action (the rollout plot draws each).
    action_labels = ("chose τ = -1 N m", "chose τ = 0", "chose τ = +1 N m")
    env_name = "Acrobot"

    def default_params(self) -> ac.AcrobotParams:
        return ac.AcrobotParams()

    def reset(self, key, params):
        return ac.reset(key, params)

    def step(self, params, state, action):
        torque = action @ jnp.asarray(ac.TORQUES, action.dtype)
        next_state = ac.step(params, state, torque)
        done = ac.terminated(next_state)
        reward = jnp.where(done, 0.0, -1.0).astype(next_state.dtype)
        return next_state, reward, done

    def observe(self, state):
        return ac.observe(state)

    def state_from_observation(self, observation):
        # The state's angles are wrapped into [-pi, pi], the range of atan2: exact to rounding.
        cos1, sin1, cos2, sin2 = observation[0], observation[1], observation[2], observation[3]
        return jnp.stack(
            [jnp.arctan2(sin1, cos1), jnp.arctan2(sin2, cos2), observation[4], observation[5]]
        )

    def step_loss(self, name: str) -> StepLoss:
        if name == "power":
            return _power
        if name in ("pump", "reach"):
            weight = GOAL_WEIGHT if name == "pump" else REACH_GOAL_WEIGHT

            def pump(params, state, action, next_state, reward):
                below = jax.nn.sigmoid((ac.GOAL_HEIGHT - ac.tip_height(next_state)) / GOAL_SOFTNESS)
                return _power(params, state, action, next_state, reward) + weight * below

            return pump
        raise KeyError(name)

    def default_plan_config(self) -> PlanConfig:
        """``diffcontrol plan acrobot``: PlanConfig's planner (box-iLQR over H = 20 on the
        relaxed 3-way choice) with the ``reach`` loss."""
        return PlanConfig(loss="reach")

    def default_config(self) -> TrainConfig:
        # 40-step windows (8 s, about two swings) see the energy a pumping pattern gains.
        # The evaluation returns wander by a few points between evaluation points, so the
        # best of 10 on 256 simulated episodes is kept. Four restarts in one program: some
        # initialisations rest where the pumping gradient vanishes and never swing.
        return TrainConfig(
            population=4,
            updates=150,
            batch=32,
            window=40,
            horizon=500,
            learning_rate=3e-3,
            lr_schedule="cosine",
            grad_clip=1.0,
            hidden=(64, 64),
            activation="tanh",
            eval_every=15,
            eval_episodes=256,
        )

    def gym_action(self, action: np.ndarray) -> Any:
        return int(np.argmax(np.asarray(action).reshape(-1)))

    def frames(self, recording: Any, every: int):
        """One matplotlib figure per drawn frame of ``recording`` (every ``every``-th state):
        the two links, the goal line, the time and the torque."""
        from ._scene import close, scene  # matplotlib

        params = self.default_params()
        l1, l2 = float(params.link_length_1), float(params.link_length_2)
        reach = l1 + l2 + 0.2
        fig, ax = scene(3.2, 3.2, (-reach, reach), (-reach, reach))
        ax.plot([-reach, reach], [ac.GOAL_HEIGHT, ac.GOAL_HEIGHT], color="0.3", lw=1)
        (links,) = ax.plot([], [], lw=5, color="#4d6fcc", solid_capstyle="round")
        (joints,) = ax.plot([], [], "o", color="#3a9a4a", ms=6)
        text = ax.text(-reach + 0.05, reach - 0.3, "", fontsize=8, family="monospace")
        for i in range(0, recording.states.shape[0], every):
            theta1, theta2 = recording.states[i, 0], recording.states[i, 1]
            elbow = (l1 * np.sin(theta1), -l1 * np.cos(theta1))
            tip = (elbow[0] + l2 * np.sin(theta1 + theta2), elbow[1] - l2 * np.cos(theta1 + theta2))
            links.set_data([0.0, elbow[0], tip[0]], [0.0, elbow[1], tip[1]])
            joints.set_data([0.0, elbow[0]], [0.0, elbow[1]])
            a = recording.actions[min(i, len(recording.actions) - 1)]
            torque = float(np.asarray(ac.TORQUES)[int(np.argmax(a))])
            text.set_text(f"t={i * recording.dt:5.1f} s  τ={torque:+.0f} N m")
            yield fig
        close(fig)


GOAL_WEIGHT = 2.0
"""``w`` of the ``pump`` loss: the weight of the soft not-at-the-goal indicator."""
REACH_GOAL_WEIGHT = 30.0
"""``w`` of the ``reach`` loss, the planner's: the same indicator weighted past the power."""
GOAL_SOFTNESS = 0.5
"""``s`` of the ``pump`` loss (link lengths): the width of the indicator's step at the line."""


def _power(params, state, action, next_state, reward):
    """Minus the power the motor puts in, ``-tau theta2_dot`` (W), on the pre-step speed."""
    return -(action @ jnp.asarray(ac.TORQUES, action.dtype)) * state[3]
